"""Batched time integration: B simulations (same mesh, time step and duration; different
parameters and, optionally, different model extensions) advanced in lock-step, with the sample
index innermost so the CSR products and the triangular solves vectorise across samples.

Layouts (b = sample index, innermost / contiguous):
  state u, v, a, work vectors : (n, B)
  CSR values kval, mval, dval : (nnz, B)   (per-sample values, same pattern)
  Cholesky factor values Lx   : (nnz_L, B) (per-sample values on the system's pattern Lp, Lj)
Per-sample (scalar, cheap) parts reuse :func:`_kernels.surface_loads`,
:func:`_kernels.contact_correct_ws` and :func:`_kernels.subglottal_step` unchanged, so each sample
follows the arithmetic of :func:`_kernels.integrate_coupled` operation for operation.
The loop around them is a copy of ``integrate_ws``'s, not shared phase functions: those (inlined) take views
and argument tuples built per sample and step, which cost the lock-step kernel 5-9 % on the coarse mesh and
the scalar one 4-8 %.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._kernels import (
    contact_correct_ws,
    contact_layer_ws,
    projection_impulse,
    step_coefficients,
    subglottal_step,
    surface_loads,
)


@njit(cache=True)
def chol_solve_many(Lp, Lj, Lx, r, nb=-1) -> None:
    """Solve (L_b L_b^T) x_b = r[:, b] in place for the first ``nb`` samples b (all when nb < 0; Lx (nnz_L, B))."""
    n = r.shape[0]
    B = r.shape[1] if nb < 0 else nb
    for i in range(n):
        end = Lp[i + 1] - 1
        for q in range(Lp[i], end):
            j = Lj[q]
            for b in range(B):
                r[i, b] -= Lx[q, b] * r[j, b]
        for b in range(B):
            r[i, b] *= Lx[end, b]
    for i in range(n - 1, -1, -1):
        end = Lp[i + 1] - 1
        for b in range(B):
            r[i, b] *= Lx[end, b]
        for q in range(Lp[i], end):
            j = Lj[q]
            for b in range(B):
                r[j, b] -= Lx[q, b] * r[i, b]


@njit(cache=True)
def _move_column(x, src, dst) -> None:
    for i in range(x.shape[0]):
        x[i, dst] = x[i, src]


@njit(cache=True)
def _move_sample(kval, mval, dval, Lx, u, v, a, src, dst) -> None:
    """Move sample ``src``'s columns of every (., B) array the vectorised loops read into slot ``dst``."""
    _move_column(kval, src, dst)
    _move_column(mval, src, dst)
    _move_column(dval, src, dst)
    _move_column(Lx, src, dst)
    _move_column(u, src, dst)
    _move_column(v, src, dst)
    _move_column(a, src, dst)


@njit(cache=True)
def integrate_many(stp, pat, mod, cpl, stop, mat, st, out, status):
    """Batched :func:`_kernels.integrate_coupled`: the groups of :mod:`._args` with per-sample fields batched.

    mat: kval, mval, dval (nnz, B); Lx (nnz_L, B); G (B, n, m). st: u, v, a (n, B).
    mod: p_sub, sep_ratio, x_mid (B,) (the rest shared). cpl: sub_coef (B, n_modes, 3) subglottal resonators
    per sample (n_modes = 0: no coupling; a sample with fewer modes is padded with zero rows, which add
    exactly 0 Pa); kc, cc (B, m) the contact layer per sample (ignored when ``layer`` is False).
    out: width, gsep (B, n_steps); lam, proj (B, n_steps, m); p_in (B, n_steps) (written only when
    n_modes > 0), else (B, 0); traj_u, traj_v (B, n_traj, n); stop (B,) (the step a sample settled at, 0 =
    ran to the end). stop: the settled-response stop of ``integrate_coupled``, per sample.
    status : (B,) int64, in/out: a sample entering with status != 0 is skipped; one whose
    state becomes non-finite or exceeds ``blowup`` at step k gets status k (-k when its contact
    active set did not settle, as in ``integrate``) and leaves the block while the others continue.

    A sample that fails or stops leaves the block: the columns of the last active sample move into its
    slot (``kval``, ``mval``, ``dval``, ``Lx``, ``u``, ``v``, ``a`` are permuted in place and hold no
    meaning afterwards), so the vectorised loops run over the active samples only. Each sample's
    arithmetic is unchanged by the moves (the loops over samples are independent).
    """
    n_steps, h, am, af, beta, gamma = stp
    indptr, indices, Lp, Lj, sdx, sdz, sX, sZ = pat
    p_sub, p_sup, sep_ratio, x_mid, closed_tol, g_reg, flow, blowup = mod
    sub_coef, flow_coef, layer, kc, cc = cpl
    stop_window, stop_width, stop_vel = stop
    kval, mval, dval, Lx, G = mat
    u, v, a = st
    width, gsep_out, lam_out, proj_out, p_in_out, traj_every, traj_u, traj_v, stop_out = out
    n, B = u.shape
    m = sdx.size
    nmod = sub_coef.shape[1]
    c0, c2, c3, m_v, m_a, d_v, d_a, lam_scale = step_coefficients(h, am, af, beta, gamma)
    y1 = np.empty((n, B))
    y2 = np.empty((n, B))
    r = np.empty((n, B))
    ws_u0 = np.empty(n)
    ws_S = np.empty((m, m))
    ws_rhs = np.empty(m)
    ws_idx = np.empty(m, dtype=np.int64)
    ws_keff = np.empty(m)
    ws_bb = np.empty(m)
    wl = 1.0 - af
    xs = np.empty(m)
    zs = np.empty(m)
    gap = np.empty(m)
    fx = np.zeros((B, m))
    fz = np.zeros((B, m))
    pres = np.empty(m)
    lam = np.zeros((B, m))
    active = np.zeros((B, m), dtype=np.bool_)
    unsettled = np.zeros(B, dtype=np.bool_)
    umax = np.zeros(B)
    sub_p1 = np.zeros((B, nmod))
    sub_p2 = np.zeros((B, nmod))
    q1 = np.zeros(B)
    q2 = np.zeros(B)
    p_in = p_sub.copy()
    # settled-response detection, per sample (see _kernels.integrate_coupled)
    win_v = np.zeros(B)
    win_hi = np.full(B, -np.inf)
    win_lo = np.full(B, np.inf)
    prev_v = np.full(B, np.inf)
    prev_quiet = np.zeros(B, dtype=np.bool_)
    vmax = np.zeros(B)
    leave = np.zeros(B, dtype=np.bool_)
    ntr_of = np.zeros(B, dtype=np.int64)
    # slot s holds sample orig[s]; slots 0 .. nb - 1 are active
    orig = np.empty(B, dtype=np.int64)
    nb = 0
    for b in range(B):
        if status[b] == 0:
            orig[nb] = b
            if nb != b:
                _move_sample(kval, mval, dval, Lx, u, v, a, b, nb)
            nb += 1
    ntr = 0
    for k in range(1, n_steps + 1):
        if nb == 0:
            break
        # flow loads, per sample
        for s in range(nb):
            b = orig[s]
            xm = x_mid[b]
            for j in range(m):
                if sdx[j] >= 0:
                    xs[j] = sX[j] + u[sdx[j], s]
                    zs[j] = sZ[j] + u[sdz[j], s]
                else:
                    xs[j] = sX[j]
                    zs[j] = sZ[j]
                gap[j] = xm - xs[j]
            surface_loads(
                xs, zs, sX, sZ, gap, p_in[b], p_sup, sep_ratio[b], closed_tol, g_reg, fx[s], fz[s], pres, flow
            )
        for i in range(n):
            for s in range(nb):
                y1[i, s] = m_v * v[i, s] + m_a * a[i, s]
                y2[i, s] = d_v * v[i, s] + d_a * a[i, s]
        for i in range(n):
            for s in range(nb):
                r[i, s] = 0.0
            for p in range(indptr[i], indptr[i + 1]):
                j = indices[p]
                for s in range(nb):
                    r[i, s] += mval[p, s] * y1[j, s] + dval[p, s] * y2[j, s] - kval[p, s] * u[j, s]
        for s in range(nb):
            for j in range(m):
                if sdx[j] >= 0:
                    r[sdx[j], s] += fx[s, j]
                    r[sdz[j], s] += fz[s, j]
        chol_solve_many(Lp, Lj, Lx, r, nb)
        for i in range(n):
            for s in range(nb):
                r[i, s] += u[i, s]  # r is now u_{n+1} before contact
        for s in range(nb):
            b = orig[s]
            # in place on the sample's (strided) column; returns at once when nothing penetrates
            if layer:
                settled = contact_layer_ws(
                    r[:, s],
                    u[:, s],
                    h,
                    wl,
                    sdx,
                    sX,
                    x_mid[b],
                    G[b],
                    kc[b],
                    cc[b],
                    lam[s],
                    active[s],
                    50,
                    ws_u0,
                    ws_S,
                    ws_rhs,
                    ws_idx,
                    ws_keff,
                    ws_bb,
                )
            else:
                settled = contact_correct_ws(
                    r[:, s], sdx, sX, x_mid[b], G[b], lam[s], active[s], 50, ws_u0, ws_S, ws_rhs, ws_idx
                )
            unsettled[s] = settled < 0  # contact did not settle: fails with status -k below
        for s in range(nb):
            umax[s] = 0.0
            vmax[s] = 0.0
        for i in range(n):
            for s in range(nb):
                du = r[i, s] - u[i, s]
                an = c0 * du - c2 * v[i, s] - c3 * a[i, s]
                v[i, s] = v[i, s] + h * ((1.0 - gamma) * a[i, s] + gamma * an)
                a[i, s] = an
                u[i, s] = r[i, s]
                # NaN-propagating running max of |u| (a NaN makes the test below fail)
                au = abs(r[i, s])
                umax[s] = au if not (au <= umax[s]) else umax[s]
        n_leave = 0
        for s in range(nb):
            b = orig[s]
            leave[s] = False
            bad = not (umax[s] < blowup)
            if unsettled[s] or bad:
                status[b] = -k if unsettled[s] else k
                leave[s] = True
                n_leave += 1
                continue
            xm = x_mid[b]
            for j in range(m):
                if active[s, j] and not layer:
                    d = sdx[j]
                    proj_out[b, k - 1, j] = projection_impulse(indptr, mval[:, s], d, v[d, s], a[d, s], h, gamma)
                    v[sdx[j], s] = 0.0
                    a[sdx[j], s] = 0.0
            gmin = 1e300
            for j in range(m):
                xj = sX[j] + (u[sdx[j], s] if sdx[j] >= 0 else 0.0)
                g = xm - xj
                if g < gmin:
                    gmin = g
                lam_out[b, k - 1, j] = -lam[s, j] * lam_scale
            width[b, k - 1] = 2.0 * (gmin if gmin > 0.0 else 0.0)
            gsep_out[b, k - 1] = sep_ratio[b] * gmin if gmin > closed_tol else 0.0
            if nmod > 0:
                dpq = p_in[b] - p_sup
                q = flow_coef * gsep_out[b, k - 1] * np.sqrt(dpq) if dpq > 0.0 else 0.0
                p_in[b] = p_sub[b] - subglottal_step(sub_coef[b], sub_p1[b], sub_p2[b], q, q2[b])
                q2[b] = q1[b]
                q1[b] = q
                p_in_out[b, k - 1] = p_in[b]
        if traj_every > 0 and k % traj_every == 0 and ntr < traj_u.shape[1]:
            for s in range(nb):
                if not leave[s]:
                    b = orig[s]
                    for i in range(n):
                        traj_u[b, ntr, i] = u[i, s]
                        traj_v[b, ntr, i] = v[i, s]
                    ntr_of[b] = ntr + 1
            ntr += 1
        if stop_window > 0:
            for i in range(n):
                for s in range(nb):
                    av = abs(v[i, s])
                    vmax[s] = av if av > vmax[s] else vmax[s]
            for s in range(nb):
                if leave[s]:
                    continue
                b = orig[s]
                if vmax[s] > win_v[b]:
                    win_v[b] = vmax[s]
                wk = width[b, k - 1]
                if wk > win_hi[b]:
                    win_hi[b] = wk
                if wk < win_lo[b]:
                    win_lo[b] = wk
                if k % stop_window == 0:
                    quiet = win_hi[b] - win_lo[b] <= stop_width and win_v[b] <= stop_vel and win_v[b] <= prev_v[b]
                    if quiet and prev_quiet[b]:
                        stop_out[b] = k
                        leave[s] = True
                        n_leave += 1
                        for kk in range(k, n_steps):
                            width[b, kk] = width[b, k - 1]
                            gsep_out[b, kk] = gsep_out[b, k - 1]
                            for j in range(m):
                                lam_out[b, kk, j] = lam_out[b, k - 1, j]
                                proj_out[b, kk, j] = proj_out[b, k - 1, j]
                            if nmod > 0:
                                p_in_out[b, kk] = p_in_out[b, k - 1]
                        if traj_every > 0:
                            for t in range(ntr_of[b], traj_u.shape[1]):
                                for i in range(n):
                                    traj_u[b, t, i] = u[i, s]
                                    traj_v[b, t, i] = v[i, s]
                        continue
                    prev_quiet[b] = quiet
                    prev_v[b] = win_v[b]
                    win_v[b] = 0.0
                    win_hi[b] = -np.inf
                    win_lo[b] = np.inf
        if n_leave > 0:
            # compact: the last active slots move into the leaving ones (slot order is irrelevant)
            s = 0
            while s < nb:
                if leave[s]:
                    last = nb - 1
                    if last != s:
                        _move_sample(kval, mval, dval, Lx, u, v, a, last, s)
                        orig[s] = orig[last]
                        leave[s] = leave[last]
                    nb -= 1
                else:
                    s += 1
    return 0
