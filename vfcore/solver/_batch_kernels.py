"""Batched time integration: B simulations (same mesh and config, different parameters)
advanced in lock-step, with the sample index innermost so the CSR products and the band
solve vectorise across samples.

Layouts (b = sample index, innermost / contiguous):
  state u, v, a, work vectors : (n, B)
  CSR values kval, mval, dval : (nnz, B)   (per-sample values, same pattern)
  band Cholesky factors Lb    : (n, bw + 1, B)  (see ``_kernels`` for the band storage)
Per-sample (scalar, cheap) parts reuse :func:`_kernels.surface_loads` and
:func:`_kernels.contact_correct` unchanged, so each sample follows the arithmetic of
:func:`_kernels.integrate` operation for operation.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._kernels import contact_correct, step_coefficients, surface_loads


@njit(cache=True, fastmath=True)
def band_solve_many(Lb: np.ndarray, r: np.ndarray, s: np.ndarray) -> None:
    """Solve (L_b L_b^T) x_b = r[:, b] in place for every sample b. ``s`` (B,) work."""
    n, w, B = Lb.shape
    bw = w - 1
    for i in range(n):
        for b in range(B):
            s[b] = r[i, b]
        j0 = max(0, i - bw)
        off = bw - i
        for j in range(j0, i):
            for b in range(B):
                s[b] -= Lb[i, j + off, b] * r[j, b]
        for b in range(B):
            r[i, b] = s[b] / Lb[i, bw, b]
    for i in range(n - 1, -1, -1):
        for b in range(B):
            s[b] = r[i, b] / Lb[i, bw, b]
            r[i, b] = s[b]
        j0 = max(0, i - bw)
        off = bw - i
        for j in range(j0, i):
            for b in range(B):
                r[j, b] -= Lb[i, j + off, b] * s[b]


@njit(cache=True, fastmath=True)
def integrate_many(n_steps, h, am, af, beta, gamma, indptr, indices, kval, mval, dval, Lb, G, sdx, sdz, sX, sZ,
                   u, v, a, p_sub, p_sup, sep_ratio, x_mid, closed_tol, g_reg, blowup,
                   width, gsep_out, lam_out, traj_every, traj_u, traj_v, status):
    """Batched :func:`_kernels.integrate`.

    kval, mval, dval : (nnz, B); Lb : (n, bw + 1, B); G : (B, n, m); u, v, a : (n, B);
    p_sub, x_mid : (B,); width, gsep_out : (B, n_steps); lam_out : (B, n_steps, m);
    traj_u, traj_v : (B, n_traj, n). status : (B,) int64, in/out: a sample entering with
    status != 0 is skipped; one whose state becomes non-finite or exceeds ``blowup`` at step
    k gets status k (-k when its contact active set did not settle, as in ``integrate``) and is
    frozen (its state zeroed) while the others continue.
    """
    n, B = u.shape
    m = sdx.size
    c0, c2, c3, m_v, m_a, d_v, d_a, lam_scale = step_coefficients(h, am, af, beta, gamma)
    y1 = np.empty((n, B))
    y2 = np.empty((n, B))
    r = np.empty((n, B))
    acc = np.zeros(B)
    rb = np.empty(n)
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
            surface_loads(xs, zs, sX, sZ, gap, p_sub[b], p_sup, sep_ratio, closed_tol, g_reg, fx[b], fz[b], pres)
        for i in range(n):
            for b in range(B):
                y1[i, b] = m_v * v[i, b] + m_a * a[i, b]
                y2[i, b] = d_v * v[i, b] + d_a * a[i, b]
        for i in range(n):
            for b in range(B):
                acc[b] = 0.0
            for p in range(indptr[i], indptr[i + 1]):
                j = indices[p]
                for b in range(B):
                    acc[b] += mval[p, b] * y1[j, b] + dval[p, b] * y2[j, b] - kval[p, b] * u[j, b]
            for b in range(B):
                r[i, b] = acc[b]
        for b in range(B):
            if not live[b]:
                continue
            for j in range(m):
                if sdx[j] >= 0:
                    r[sdx[j], b] += fx[b, j]
                    r[sdz[j], b] += fz[b, j]
        band_solve_many(Lb, r, acc)
        for i in range(n):
            for b in range(B):
                r[i, b] += u[i, b]          # r is now u_{n+1} before contact
        for b in range(B):
            if not live[b]:
                continue
            for i in range(n):
                rb[i] = r[i, b]
            if contact_correct(rb, sdx, sX, x_mid[b], G[b], lam[b], active[b], 50) < 0:
                unsettled[b] = True     # contact did not settle: fails with status -k below
            for i in range(n):
                r[i, b] = rb[i]
        for i in range(n):
            for b in range(B):
                du = r[i, b] - u[i, b]
                an = c0 * du - c2 * v[i, b] - c3 * a[i, b]
                v[i, b] = v[i, b] + h * ((1.0 - gamma) * a[i, b] + gamma * an)
                a[i, b] = an
                u[i, b] = r[i, b]
        for b in range(B):
            if not live[b]:
                continue
            bad = False
            for i in range(n):
                if not (abs(u[i, b]) < blowup):
                    bad = True
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
                if active[b, j]:
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
            gsep_out[b, k - 1] = sep_ratio * gmin if gmin > closed_tol else 0.0
        if traj_every > 0 and k % traj_every == 0 and ntr < traj_u.shape[1]:
            for b in range(B):
                if live[b]:
                    for i in range(n):
                        traj_u[b, ntr, i] = u[i, b]
                        traj_v[b, ntr, i] = v[i, b]
            ntr += 1
    return 0
