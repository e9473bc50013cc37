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
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._kernels import contact_correct_ws, contact_layer_ws, projection_impulse, step_coefficients, subglottal_step, surface_loads


@njit(cache=True)
def chol_solve_many(Lp, Lj, Lx, r) -> None:
    """Solve (L_b L_b^T) x_b = r[:, b] in place for every sample b (Lx (nnz_L, B))."""
    n, B = r.shape
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
def integrate_many(n_steps, h, am, af, beta, gamma, indptr, indices, kval, mval, dval, Lp, Lj, Lx, G,
                   sdx, sdz, sX, sZ, u, v, a, p_sub, p_sup, sep_ratio, x_mid, closed_tol, g_reg, blowup,
                   width, gsep_out, lam_out, traj_every, traj_u, traj_v, status, sub_coef, flow_coef, p_in_out,
                   proj_out, layer, kc, cc):
    """Batched :func:`_kernels.integrate_coupled`.

    kval, mval, dval : (nnz, B); Lx : (nnz_L, B); G : (B, n, m); u, v, a : (n, B);
    p_sub, sep_ratio, x_mid : (B,); width, gsep_out : (B, n_steps); lam_out : (B, n_steps, m);
    traj_u, traj_v : (B, n_traj, n). sub_coef : (B, n_modes, 3) subglottal resonators per sample
    (n_modes = 0: no coupling; a sample with fewer modes is padded with zero rows, which add
    exactly 0 Pa); p_in_out : (B, n_steps) inlet pressure (written only when n_modes > 0).
    status : (B,) int64, in/out: a sample entering with status != 0 is skipped; one whose
    state becomes non-finite or exceeds ``blowup`` at step k gets status k (-k when its contact
    active set did not settle, as in ``integrate``) and is frozen (its state zeroed) while the
    others continue. proj_out : (B, n_steps, m), the projection impulses of ``integrate_coupled``
    (:func:`_kernels.projection_impulse` on the sample's column of mval). layer, kc (B, m), cc (B, m):
    the contact law of ``integrate_coupled`` (compliant layer per sample; ignored when ``layer`` is False).
    """
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
    live = np.zeros(B, dtype=np.bool_)
    unsettled = np.zeros(B, dtype=np.bool_)
    umax = np.zeros(B)
    sub_p1 = np.zeros((B, nmod))
    sub_p2 = np.zeros((B, nmod))
    q1 = np.zeros(B)
    q2 = np.zeros(B)
    p_in = p_sub.copy()
    for b in range(B):
        live[b] = status[b] == 0
        if not live[b]:
            for i in range(n):
                u[i, b] = 0.0
                v[i, b] = 0.0
                a[i, b] = 0.0
    ntr = 0
    for k in range(1, n_steps + 1):
        # flow loads, per sample
        for b in range(B):
            if not live[b]:
                continue
            xm = x_mid[b]
            for j in range(m):
                if sdx[j] >= 0:
                    xs[j] = sX[j] + u[sdx[j], b]
                    zs[j] = sZ[j] + u[sdz[j], b]
                else:
                    xs[j] = sX[j]
                    zs[j] = sZ[j]
                g = xm - xs[j]
                gap[j] = g if g > 0.0 else 0.0
            surface_loads(xs, zs, sX, sZ, gap, p_in[b], p_sup, sep_ratio[b], closed_tol, g_reg, fx[b], fz[b],
                          pres)
        for i in range(n):
            for b in range(B):
                y1[i, b] = m_v * v[i, b] + m_a * a[i, b]
                y2[i, b] = d_v * v[i, b] + d_a * a[i, b]
        for i in range(n):
            for b in range(B):
                r[i, b] = 0.0
            for p in range(indptr[i], indptr[i + 1]):
                j = indices[p]
                for b in range(B):
                    r[i, b] += mval[p, b] * y1[j, b] + dval[p, b] * y2[j, b] - kval[p, b] * u[j, b]
        for b in range(B):
            if not live[b]:
                continue
            for j in range(m):
                if sdx[j] >= 0:
                    r[sdx[j], b] += fx[b, j]
                    r[sdz[j], b] += fz[b, j]
        chol_solve_many(Lp, Lj, Lx, r)
        for i in range(n):
            for b in range(B):
                r[i, b] += u[i, b]          # r is now u_{n+1} before contact
        for b in range(B):
            if not live[b]:
                continue
            # in place on the sample's (strided) column; returns at once when nothing penetrates
            if layer:
                settled = contact_layer_ws(r[:, b], u[:, b], h, wl, sdx, sX, x_mid[b], G[b], kc[b], cc[b], lam[b],
                                           active[b], 50, ws_u0, ws_S, ws_rhs, ws_idx, ws_keff, ws_bb)
            else:
                settled = contact_correct_ws(r[:, b], sdx, sX, x_mid[b], G[b], lam[b], active[b], 50, ws_u0, ws_S,
                                             ws_rhs, ws_idx)
            if settled < 0:
                unsettled[b] = True     # contact did not settle: fails with status -k below
        for b in range(B):
            umax[b] = 0.0
        for i in range(n):
            for b in range(B):
                du = r[i, b] - u[i, b]
                an = c0 * du - c2 * v[i, b] - c3 * a[i, b]
                v[i, b] = v[i, b] + h * ((1.0 - gamma) * a[i, b] + gamma * an)
                a[i, b] = an
                u[i, b] = r[i, b]
                # NaN-propagating running max of |u| (a NaN makes the test below fail)
                au = abs(r[i, b])
                umax[b] = au if not (au <= umax[b]) else umax[b]
        for b in range(B):
            if not live[b]:
                continue
            bad = not (umax[b] < blowup)
            if unsettled[b] or bad:
                status[b] = -k if unsettled[b] else k
                live[b] = False
                for i in range(n):
                    u[i, b] = 0.0
                    v[i, b] = 0.0
                    a[i, b] = 0.0
                for j in range(m):
                    fx[b, j] = 0.0
                    fz[b, j] = 0.0
                continue
            xm = x_mid[b]
            for j in range(m):
                if active[b, j] and not layer:
                    d = sdx[j]
                    proj_out[b, k - 1, j] = projection_impulse(indptr, mval[:, b], d, v[d, b], a[d, b], h, gamma)
                    v[sdx[j], b] = 0.0
                    a[sdx[j], b] = 0.0
            gmin = 1e300
            for j in range(m):
                xj = sX[j] + (u[sdx[j], b] if sdx[j] >= 0 else 0.0)
                g = xm - xj
                if g < gmin:
                    gmin = g
                lam_out[b, k - 1, j] = -lam[b, j] * lam_scale
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
            for b in range(B):
                if live[b]:
                    for i in range(n):
                        traj_u[b, ntr, i] = u[i, b]
                        traj_v[b, ntr, i] = v[i, b]
            ntr += 1
    return 0
