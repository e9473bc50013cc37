"""Batched time integration: B simulations (same mesh, time step and duration; different
parameters and, optionally, different model extensions) advanced in lock-step, with the sample
index innermost so the CSR products and the triangular solves vectorise across samples.

Layouts (b = sample index, innermost / contiguous):
  state u, v, a, work vectors : (n, B)
  CSR values kval, mval, dval : (nnz, B)   (per-sample values, same pattern)
  Cholesky factor values Lx   : (nnz_L, B) (per-sample values on the system's pattern Lp, Lj)
The per-sample (scalar, cheap) phases of a step are those of :func:`_kernels.integrate_ws`
(``sample_loads``, ``sample_contact``, ``sample_record``, ``sample_window``), run on each sample's views, so
each sample follows the arithmetic of :func:`_kernels.integrate_coupled` operation for operation.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._args import Coupling, Model, Outputs, State, Work
from ._kernels import sample_contact, sample_loads, sample_record, sample_start, sample_window, step_coefficients


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


@njit(cache=True, inline='always')     # see the sample_* functions of _kernels
def _sample(mod, cpl, mat, st, out, ws, s, b):
    """The groups of :func:`._kernels.integrate_ws` for the sample ``b`` in slot ``s``: its entries of the
    per-sample fields (columns of the (., B) arrays, rows of the (B, ...) ones) and the shared work arrays."""
    return (Model(mod.p_sub[b], mod.p_sup, mod.sep_ratio[b], mod.x_mid[b], mod.closed_tol, mod.g_reg, mod.flow,
                  mod.blowup),
            Coupling(cpl.sub_coef[b], cpl.flow_coef, cpl.layer, cpl.kc[b], cpl.cc[b]),
            mat.mval[:, s],
            State(st.u[:, s], st.v[:, s], st.a[:, s]),
            Outputs(out.width[b], out.gsep[b], out.lam[b], out.proj[b], out.p_in[b], out.traj_every, out.traj_u[b],
                    out.traj_v[b], out.stop[b:b + 1]),
            Work(ws.y1[:, s], ws.y2[:, s], ws.r[:, s], ws.u0, ws.xs, ws.zs, ws.gap, ws.fx[s], ws.fz[s], ws.pres,
                 ws.lam[s], ws.active[s], ws.S, ws.rhs, ws.idx, ws.keff, ws.bb, ws.sub_p1[b], ws.sub_p2[b]))


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

    The per-sample phases of a step are :func:`._kernels.integrate_ws`'s own (:func:`._kernels.sample_loads`,
    ``sample_contact``, ``sample_record``, ``sample_window``), on the sample's views; the CSR product, the
    triangular solves and the state update run here with the sample index innermost.
    """
    kval, mval, dval, Lx = mat.kval, mat.mval, mat.dval, mat.Lx
    u, v, a = st.u, st.v, st.a
    indptr, indices, sdx, sdz = pat.indptr, pat.indices, pat.sdx, pat.sdz
    n, B = u.shape
    m = sdx.size
    n_steps, h, gamma = stp.n_steps, stp.h, stp.gamma
    blowup = mod.blowup
    nmod = cpl.sub_coef.shape[1]
    c0, c2, c3, m_v, m_a, d_v, d_a, lam_scale = step_coefficients(h, stp.am, stp.af, stp.beta, gamma)
    ws = Work(np.empty((n, B)), np.empty((n, B)), np.empty((n, B)), np.empty(n), np.empty(m), np.empty(m),
              np.empty(m), np.zeros((B, m)), np.zeros((B, m)), np.empty(m), np.zeros((B, m)),
              np.zeros((B, m), dtype=np.bool_), np.empty((m, m)), np.empty(m), np.empty(m, dtype=np.int64),
              np.empty(m), np.empty(m), np.zeros((B, nmod)), np.zeros((B, nmod)))
    y1, y2, r, fx, fz = ws.y1, ws.y2, ws.r, ws.fx, ws.fz
    unsettled = np.zeros(B, dtype=np.bool_)
    umax = np.zeros(B)
    vmax = np.zeros(B)
    leave = np.zeros(B, dtype=np.bool_)
    # each sample's carry between steps (:func:`._kernels.sample_start`), one array per entry
    p_in = np.empty(B)
    q1 = np.empty(B)
    q2 = np.empty(B)
    ntr = np.empty(B, dtype=np.int64)
    win_v = np.empty(B)
    win_hi = np.empty(B)
    win_lo = np.empty(B)
    prev_v = np.empty(B)
    prev_quiet = np.empty(B, dtype=np.bool_)
    # slot s holds sample orig[s]; slots 0 .. nb - 1 are active
    orig = np.empty(B, dtype=np.int64)
    nb = 0
    for b in range(B):
        (p_in[b], q1[b], q2[b], ntr[b], win_v[b], win_hi[b], win_lo[b], prev_v[b],
         prev_quiet[b]) = sample_start(_sample(mod, cpl, mat, st, out, ws, 0, b)[0])
        if status[b] == 0:
            orig[nb] = b
            if nb != b:
                _move_sample(kval, mval, dval, Lx, u, v, a, b, nb)
            nb += 1
    for k in range(1, n_steps + 1):
        if nb == 0:
            break
        for s in range(nb):
            b = orig[s]
            mod_b, _, _, st_b, _, ws_b = _sample(mod, cpl, mat, st, out, ws, s, b)
            sample_loads(pat, mod_b, p_in[b], st_b.u, ws_b)
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
        chol_solve_many(pat.Lp, pat.Lj, Lx, r, nb)
        for i in range(n):
            for s in range(nb):
                r[i, s] += u[i, s]          # r is now u_{n+1} before contact
        for s in range(nb):
            b = orig[s]
            mod_b, cpl_b, _, st_b, _, ws_b = _sample(mod, cpl, mat, st, out, ws, s, b)
            # in place on the sample's (strided) column; returns at once when nothing penetrates
            unsettled[s] = sample_contact(stp, pat, mod_b, cpl_b, mat.G[b], st_b.u, ws_b) < 0
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
            if unsettled[s] or not (umax[s] < blowup):
                status[b] = -k if unsettled[s] else k
                leave[s] = True
                n_leave += 1
                continue
            mod_b, cpl_b, mval_b, st_b, out_b, ws_b = _sample(mod, cpl, mat, st, out, ws, s, b)
            (p_in[b], q1[b], q2[b], ntr[b], win_v[b], win_hi[b], win_lo[b], prev_v[b],
             prev_quiet[b]) = sample_record(k, stp, pat, mod_b, cpl_b, mval_b, st_b, out_b, ws_b, lam_scale,
                                            (p_in[b], q1[b], q2[b], ntr[b], win_v[b], win_hi[b], win_lo[b],
                                             prev_v[b], prev_quiet[b]))
        if stop.window > 0:
            for i in range(n):
                for s in range(nb):
                    av = abs(v[i, s])
                    vmax[s] = av if av > vmax[s] else vmax[s]
            for s in range(nb):
                if leave[s]:
                    continue
                b = orig[s]
                _, cpl_b, _, st_b, out_b, _ = _sample(mod, cpl, mat, st, out, ws, s, b)
                settled, (p_in[b], q1[b], q2[b], ntr[b], win_v[b], win_hi[b], win_lo[b], prev_v[b],
                          prev_quiet[b]) = sample_window(k, n_steps, stop, cpl_b, st_b, out_b, vmax[s],
                                                         (p_in[b], q1[b], q2[b], ntr[b], win_v[b], win_hi[b],
                                                          win_lo[b], prev_v[b], prev_quiet[b]))
                if settled:
                    leave[s] = True
                    n_leave += 1
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
