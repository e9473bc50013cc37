"""numba kernels of the time integration. Every constant is an argument.

Factor storage: the lower Cholesky factor L of the effective stiffness in row CSR
(``Lp``, ``Lj``, ``Lx``), columns ascending and the diagonal last in each row, stored as
its reciprocal (see :func:`sparse_cholesky`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._args import Coupling, Stop, Work
from ._flow import lump_pressures, smoothstep, surface_loads_continuous

#: ``flow`` argument of the kernels: the paper's node-wise load, or the continuous one of :mod:`._flow`
FLOW_PAPER = 0
FLOW_CONTINUOUS = 1

# No fast-math anywhere in the solver kernels (strict IEEE arithmetic, every sum in source order).
# With ``reassoc`` LLVM may vectorise a reduction (a CSR row, a triangular-solve row) with an
# association order that depends on the compilation context: a kernel compiled cold gave other bits
# than the same kernel loaded from numba's cache (measured: GAWs differing by up to 22 mm^2 on a
# sensitive case). Contraction into FMAs is likewise a code-generation choice. Without fast-math the
# results are the same whether compiled or cached, and the scalar and lock-step kernels agree bit for
# bit; nothing was lost: the scalar loop got faster (143 -> 96 ms per simulation) and the lock-step one
# stayed at 37-41 ms. (The flags are literal, not a shared constant: numba's cache does not notice a
# change of a constant imported from another module.)


@njit(cache=True)
def sparse_cholesky(indptr, indices, vals, Lp, Lj, Lx) -> int:
    """Numeric Cholesky factorisation A = L L^T on a precomputed pattern (up-looking, by rows).

    A : symmetric CSR (indptr, indices, vals; both triangles stored). L : row CSR (Lp, Lj)
    from :func:`vfcore.solver.system.cholesky_pattern`, the diagonal last in each row; its values
    are written to ``Lx`` with the diagonal stored as its reciprocal 1 / L_ii (the solves
    multiply by it). Row i: L_ij = (A_ij - sum_{k<j} L_ik L_jk) / L_jj for j in the row's
    pattern, ascending, then L_ii = sqrt(A_ii - sum_k L_ik^2).
    Returns 0, or i + 1 when the leading minor of order i + 1 is not positive definite.
    """
    n = Lp.size - 1
    row = np.zeros(n)  # dense copy of the row of L being built
    for i in range(n):
        for p in range(indptr[i], indptr[i + 1]):
            j = indices[p]
            if j <= i:
                row[j] = vals[p]
        end = Lp[i + 1] - 1  # diagonal slot
        d = row[i]
        for q in range(Lp[i], end):
            j = Lj[q]
            s = row[j]
            for t in range(Lp[j], Lp[j + 1] - 1):
                s -= Lx[t] * row[Lj[t]]
            lij = s * Lx[Lp[j + 1] - 1]
            row[j] = lij
            Lx[q] = lij
            d -= lij * lij
        if not d > 0.0:
            return i + 1
        Lx[end] = 1.0 / np.sqrt(d)
        for q in range(Lp[i], Lp[i + 1]):
            row[Lj[q]] = 0.0
    return 0


@njit(cache=True)
def chol_solve(Lp, Lj, Lx, b) -> None:
    """Solve (L L^T) x = b in place, L from :func:`sparse_cholesky`."""
    n = Lp.size - 1
    for i in range(n):
        s = b[i]
        end = Lp[i + 1] - 1
        for q in range(Lp[i], end):
            s -= Lx[q] * b[Lj[q]]
        b[i] = s * Lx[end]
    for i in range(n - 1, -1, -1):
        end = Lp[i + 1] - 1
        xi = b[i] * Lx[end]
        b[i] = xi
        for q in range(Lp[i], end):
            b[Lj[q]] -= Lx[q] * xi


@njit(cache=True)
def surface_loads(xs, zs, nxs, nzs, gap, p_sub, p_sup, sep_ratio, closed_tol, g_reg, fx, fz, pres, flow):
    """Bernoulli pressures along the free surface and the nodal forces they produce.

    ``flow``: ``FLOW_PAPER`` (the paper's node-wise rule, below) or ``FLOW_CONTINUOUS``
    (:func:`._flow.surface_loads_continuous`, which takes the signed gaps as they are).

    ``g_reg`` (m, 0 = off): small-gap regularisation. While the minimum half gap ``gmin`` is
    below ``g_reg`` the open-glottis Bernoulli pressures are blended into the closed-glottis
    distribution (p_sub upstream of the minimum, p_sup downstream) with the weight
    ``w = s^2 (3 - 2 s)``, ``s = gmin / g_reg``, so the load is continuous through closure
    (see :ref:`model-closure-regularisation-a-deliberate-deviation`).

    xs, zs : (m,) current surface node coordinates (inferior -> superior), m.
    nxs, nzs : (m,) coordinates whose edges give the load directions (the reference
        configuration in the small-strain model), m.
    gap : (m,) signed half gap to the midline, m (negative while a node overlaps it); the paper's rule
        clamps it at 0 in place.
    Returns (min half gap, half gap at separation, index of closure or -1).
    Forces are per unit depth (N/m), pointing into the fold.
    """
    if flow != FLOW_PAPER:
        return surface_loads_continuous(xs, zs, nxs, nzs, gap, p_sub, p_sup, sep_ratio, g_reg, fx, fz, pres)
    m = xs.size
    for i in range(m):
        if not gap[i] > 0.0:
            gap[i] = 0.0
    imin = 0
    for i in range(m):
        if gap[i] < gap[imin]:
            imin = i
    gmin = gap[imin]
    dp = p_sub - p_sup
    iclose = -1
    gsep = 0.0
    if gmin <= closed_tol:
        # closed glottis: p_sub upstream of the first closed node, p_sup downstream
        for i in range(m):
            if gap[i] <= closed_tol:
                iclose = i
                break
        for i in range(m):
            pres[i] = p_sub if i < iclose else p_sup
    else:
        gsep = sep_ratio * gmin
        isep = m
        for i in range(imin + 1, m):
            if gap[i] >= gsep:
                isep = i
                break
        for i in range(m):
            if i < isep:
                r = gsep / gap[i]
                pres[i] = p_sub - dp * r * r
            else:
                pres[i] = p_sup
        if gmin < g_reg:
            w = smoothstep(gmin / g_reg)
            for i in range(m):
                pc = p_sub if i < imin else p_sup
                pres[i] = w * pres[i] + (1.0 - w) * pc
    lump_pressures(nxs, nzs, pres, fx, fz)
    return gmin, gsep, iclose


@njit(cache=True)
def spd_solve_lower(S, rhs, k) -> None:
    """Solve the leading k x k block of S x = rhs in place (S symmetric positive definite, its lower
    triangle filled): Cholesky S = C C^T overwriting the lower triangle, then two triangular solves."""
    for a in range(k):
        for b in range(a + 1):
            t = S[a, b]
            for c in range(b):
                t -= S[a, c] * S[b, c]
            if b == a:
                S[a, a] = math.sqrt(t)
            else:
                S[a, b] = t / S[b, b]
    for a in range(k):
        t = rhs[a]
        for c in range(a):
            t -= S[a, c] * rhs[c]
        rhs[a] = t / S[a, a]
    for a in range(k - 1, -1, -1):
        t = rhs[a]
        for c in range(a + 1, k):
            t -= S[c, a] * rhs[c]
        rhs[a] = t / S[a, a]


@njit(cache=True)
def _active_list(active, idx) -> int:
    """Write the indices of the active nodes into ``idx``; return their number."""
    k = 0
    for j in range(active.size):
        if active[j]:
            idx[k] = j
            k += 1
    return k


@njit(cache=True)
def _apply_multipliers(u, u0, G, idx, x, lam, k) -> None:
    """lam = the k multipliers ``x`` on the nodes ``idx`` (0 elsewhere); u = u0 + G[:, idx] x."""
    for j in range(lam.size):
        lam[j] = 0.0
    for a in range(k):
        lam[idx[a]] = x[a]
    for i in range(u.size):
        t = u0[i]
        for a in range(k):
            t += G[i, idx[a]] * x[a]
        u[i] = t


@njit(cache=True)
def contact_correct(u, sdx, sX, x_mid, G, lam, active, max_iter):
    """Enforce x <= x_mid on free-surface nodes with Lagrange multipliers.

    u : (n,) displacement from the unconstrained solve (corrected in place).
    G : (n, m) columns K_eff^{-1} e_{x-dof of surface node j} (zero for fixed nodes).
    lam : (m,) contact force in x on each surface node, N/m (written; <= 0 pushes laterally).
    active : (m,) work array of booleans.
    Returns the number of active-set iterations, or -1 if it did not settle.
    """
    m = sdx.size
    return contact_correct_ws(
        u,
        sdx,
        sX,
        x_mid,
        G,
        lam,
        active,
        max_iter,
        np.empty(u.size),
        np.empty((m, m)),
        np.empty(m),
        np.empty(m, dtype=np.int64),
    )


@njit(cache=True)
def contact_correct_ws(u, sdx, sX, x_mid, G, lam, active, max_iter, u0, S, rhs, idx):
    """:func:`contact_correct` with caller-owned work arrays (no allocation per call): u0 (n,),
    S (m, m), rhs (m,), idx (m,) int64.

    The active-set system S lam = rhs, S_ab = G[sdx[a], b] = e_a^T K_eff^{-1} e_b, is symmetric
    positive definite (a principal submatrix of K_eff^{-1}); it is solved by Cholesky in place.
    """
    m = sdx.size
    n = u.size
    any_pen = False
    for j in range(m):
        lam[j] = 0.0
        active[j] = False
        if sdx[j] >= 0 and sX[j] + u[sdx[j]] > x_mid:
            active[j] = True
            any_pen = True
    if not any_pen:
        return 0
    for i in range(n):
        u0[i] = u[i]
    for it in range(max_iter):
        k = _active_list(active, idx)
        for a in range(k):
            ja = idx[a]
            rhs[a] = (x_mid - sX[ja]) - u0[sdx[ja]]
            for b in range(a + 1):
                S[a, b] = G[sdx[ja], idx[b]]
        spd_solve_lower(S, rhs, k)
        _apply_multipliers(u, u0, G, idx, rhs, lam, k)
        changed = False
        for j in range(m):
            if sdx[j] < 0:
                continue
            if active[j] and lam[j] > 0.0:  # tensile: release
                active[j] = False
                changed = True
            elif (not active[j]) and sX[j] + u[sdx[j]] > x_mid * (1.0 + 1e-12):
                active[j] = True
                changed = True
        if not changed:
            return it + 1
    return -1


@njit(cache=True)
def contact_layer_ws(u, un, h, wl, sdx, sX, x_mid, G, kc, cc, lam, active, max_iter, u0, S, rhs, idx, keff, bb):
    """Midline contact through a compliant layer (Kelvin-Voigt: spring ``kc`` and dashpot ``cc`` per node).

    The force on surface node j (x, N/m) at t_{n+1} is f_j = -(kc_j d_j + cc_j (d_j - d_j^n) / h) while
    that is compressive, else 0 (no adhesion); d = sX + u - x_mid is the node's overlap with the midline
    and d^n = max(d(t_n), 0). The dashpot's rate is the backward difference of the overlap, not the
    trapezoidal velocity: the trapezoidal rule leaves a dashpot much stiffer than 1/h undamped (its
    velocity flips sign every step), which pushes nodes out of contact and back; the backward difference
    is monotone, and a compressive force then implies d_j > 0, so the active set is that of a linear
    complementarity problem with a positive definite matrix. So f_j = -(keff_j u_j + bb_j) with
    keff = kc + cc / h, and the multiplier of the alpha-weighted equation is lam_j = wl f_j
    (wl = 1 - alpha_f). For the active set A, (S_AA + diag(1 / (wl keff_A))) lam_A = -(u0_A + bb_A / keff_A),
    S_ab = G[sdx[a], b], symmetric positive definite like the rigid case (:func:`contact_correct_ws`),
    which it approaches as kc -> inf. ``cc = 0`` with ``wl = 1`` is the static problem (medial
    compression) on a spring layer.

    u : (n,) unconstrained u_{n+1} (corrected in place); un (n,) displacement at t_n; lam (m,) written;
    keff, bb (m,) work. Returns the number of active-set iterations, or -1 if it did not settle.
    """
    m = sdx.size
    n = u.size
    any_pen = False
    for j in range(m):
        lam[j] = 0.0
        active[j] = False
        d = sdx[j]
        if d < 0:
            continue
        ch = cc[j] / h
        keff[j] = kc[j] + ch
        dn = sX[j] + un[d] - x_mid
        bb[j] = keff[j] * (sX[j] - x_mid) - ch * (dn if dn > 0.0 else 0.0)
        if keff[j] * u[d] + bb[j] > 0.0:
            active[j] = True
            any_pen = True
    if not any_pen:
        return 0
    for i in range(n):
        u0[i] = u[i]
    for it in range(max_iter):
        k = _active_list(active, idx)
        for a in range(k):
            ja = idx[a]
            rhs[a] = -(u0[sdx[ja]] + bb[ja] / keff[ja])
            for b in range(a + 1):
                S[a, b] = G[sdx[ja], idx[b]]
            S[a, a] += 1.0 / (wl * keff[ja])
        spd_solve_lower(S, rhs, k)
        _apply_multipliers(u, u0, G, idx, rhs, lam, k)
        changed = False
        for j in range(m):
            d = sdx[j]
            if d < 0:
                continue
            if active[j] and lam[j] > 0.0:  # tensile: release
                active[j] = False
                changed = True
            elif (not active[j]) and keff[j] * u[d] + bb[j] > 0.0:
                active[j] = True
                changed = True
        if not changed:
            return it + 1
    return -1


def newmark_coefficients(h: float, rho_inf: float) -> tuple[float, float, float, float]:
    """(alpha_m, alpha_f, beta, gamma) of the generalised-alpha method.

    ``rho_inf = 1`` gives the Newmark average-acceleration (trapezoidal) rule of the
    paper exactly (alpha_m = alpha_f = 0, beta = 1/4, gamma = 1/2); ``rho_inf < 1``
    the Chung & Hulbert (1993) scheme, second order, unconditionally stable, with
    high-frequency spectral radius ``rho_inf``.
    """
    if rho_inf >= 1.0:
        return 0.0, 0.0, 0.25, 0.5
    am = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
    af = rho_inf / (rho_inf + 1.0)
    return am, af, 0.25 * (1.0 - am + af) ** 2, 0.5 - am + af


def effective_scales(h: float, rho_inf: float) -> tuple[float, float, float]:
    """Factors (cM, cD, cK) with K_eff = cM M + cD D + cK K."""
    am, af, beta, gamma = newmark_coefficients(h, rho_inf)
    return (1.0 - am) / (beta * h * h), (1.0 - af) * gamma / (beta * h), 1.0 - af


@njit(cache=True)
def step_coefficients(h, am, af, beta, gamma):
    """Per-step constants of the incremental generalised-alpha update (see ``integrate``).

    Returns (c0, c2, c3, m_v, m_a, d_v, d_a, lam_scale): a_{n+1} = c0 du - c2 v - c3 a;
    y1 = m_v v + m_a a (multiplies M), y2 = d_v v + d_a a (multiplies D); the contact
    multiplier of the alpha-weighted equation divided by (1 - af) is the force at t_{n+1}.
    """
    c0 = 1.0 / (beta * h * h)
    c2 = 1.0 / (beta * h)
    c3 = 0.5 / beta - 1.0
    return (
        c0,
        c2,
        c3,
        (1.0 - am) * c2,
        (1.0 - am) * c3 - am,
        -((1.0 - af) * (1.0 - gamma / beta) + af),
        -(1.0 - af) * h * (1.0 - 0.5 * gamma / beta),
        1.0 / (1.0 - af),
    )


def subglottal_coefficients(modes, h: float) -> np.ndarray:
    """(n_modes, 3) coefficients (b0, a1, a2) of the discrete subglottal resonators.

    Each mode (f_hz, zeta, Z_peak) is the parallel resonance
    ``P(s) / Q(s) = 2 zeta w Z s / (s^2 + 2 zeta w s + w^2)`` (w = 2 pi f_hz; |P/Q| = Z_peak at w),
    i.e. p'' + 2 zeta w p' + w^2 p = 2 zeta w Z dQ/dt, discretised with the bilinear (trapezoidal)
    transform prewarped at w, ``s -> c (1 - z^-1) / (1 + z^-1)``, c = w / tan(w h / 2):
    unconditionally stable, second order, and exact in peak value and frequency. The recursion is
    ``p[n] = b0 (Q[n] - Q[n-2]) - a1 p[n-1] - a2 p[n-2]`` (see :func:`subglottal_step`).
    """
    out = np.zeros((len(modes), 3))
    for i, (f, zeta, Z) in enumerate(modes):
        w = 2.0 * np.pi * f
        c = w / np.tan(0.5 * w * h)
        d1, d0 = 2.0 * zeta * w, w * w
        D = c * c + d1 * c + d0
        out[i] = (d1 * Z * c / D, 2.0 * (d0 - c * c) / D, (c * c - d1 * c + d0) / D)
    return out


@njit(cache=True)
def subglottal_step(coef, p1, p2, q, q2):
    """Advance every resonator by one step with input flow q = Q[n] (Q[n-2] = q2).

    coef : (n_modes, 3) from :func:`subglottal_coefficients`; p1, p2 : (n_modes,) p[n-1], p[n-2]
    (updated in place to p[n], p[n-1]). Returns sum_k p_k[n], Pa.
    """
    tot = 0.0
    for i in range(coef.shape[0]):
        pk = coef[i, 0] * (q - q2) - coef[i, 1] * p1[i] - coef[i, 2] * p2[i]
        p2[i] = p1[i]
        p1[i] = pk
        tot += pk
    return tot


@njit(cache=True)
def subglottal_response(q, coef):
    """Summed resonator pressure (Pa) for a prescribed flow series ``q`` (m^3/s) from rest."""
    nm = coef.shape[0]
    p1 = np.zeros(nm)
    p2 = np.zeros(nm)
    out = np.empty(q.size)
    q1 = 0.0
    q2 = 0.0
    for n in range(q.size):
        out[n] = subglottal_step(coef, p1, p2, q[n], q2)
        q2 = q1
        q1 = q[n]
    return out


@njit(cache=True)
def projection_impulse(indptr, mval, d, vd, ad, h, gamma):
    """Lateral momentum (N s/m) removed by zeroing velocity ``vd`` and acceleration ``ad`` of dof ``d``.

    Zeroing v_d changes the momentum in x by -sum_i M_id v_d (consistent mass: the column sum, equal to
    the row sum); zeroing a_d removes h (1 - gamma) a_d from the next step's velocity update,
    v_{n+1} = v_n + h ((1 - gamma) a_n + gamma a_{n+1}). Their sum, with the multiplier's impulse
    h * f, is the normal momentum the midline takes per step (exactly m v for a rigid stop).
    """
    md = 0.0
    for p in range(indptr[d], indptr[d + 1]):
        md += mval[p]
    return md * (vd + h * (1.0 - gamma) * ad)


@njit(cache=True)
def integrate(stp, pat, mod, mat, st, out):
    """:func:`integrate_coupled` without the model extensions (no subglottal resonators: the inlet pressure is
    ``mod.p_sub``; the rigid midline) and without the settled-response stop; ``out.stop`` is not written."""
    m = pat.sdx.size
    cpl = Coupling(np.zeros((0, 3)), 0.0, False, np.zeros(m), np.zeros(m))
    return integrate_coupled(stp, pat, mod, cpl, Stop(0, 0.0, 0.0), mat, st, out)


@njit(cache=True)
def integrate_coupled(stp, pat, mod, cpl, stop, mat, st, out):
    """Generalised-alpha / Newmark integration with Bernoulli loads and midline contact.

    Arguments: the groups of :mod:`._args` (``stp`` Stepper, ``pat`` Pattern, ``mod`` Model, ``cpl`` Coupling,
    ``stop`` Stop, ``mat`` Matrices, ``st`` State, ``out`` Outputs), shapes as given there.

    Incremental form: K_eff du = F - K u_n + M y1 + D y2 (see :ref:`model`). The flow
    load F is evaluated on the configuration at t_n. State u, v, a (n,) in the solver's
    dof ordering is advanced in place. Per step k (1..n_steps) writes out.width[k-1]
    (2 x min half gap, m), out.gsep[k-1] (half gap at separation, m; 0 when closed)
    and out.lam[k-1, :] (contact force per surface node, N/m, >= 0). Every
    ``out.traj_every`` steps (0 = never) u and v are stored in out.traj_u/v.
    Returns 0 on success, the (1-based) step at which the state became non-finite or
    exceeded ``mod.blowup`` metres, or minus the step at which contact did not settle.

    Subglottal coupling (``cpl.sub_coef`` (n_modes, 3) from :func:`subglottal_coefficients`; 0 rows =
    off, then the loads use ``p_sub`` and nothing else is done per step): the loads of step k use
    the inlet pressure p_in(t_{k-1}) = p_sub - sum_k p_k(t_{k-1}); after step k the flow
    Q(t_k) = flow_coef * gsep(t_k) * sqrt(max(p_in(t_{k-1}) - p_sup, 0)) (explicit: the previous
    p_in; flow_coef = 2 L sqrt(2 / rho_air)) drives the resonators, which give p_in(t_k), written
    to ``out.p_in[k-1]``. Before t = 0 the flow and the resonators are at rest (p_in(t_0) = p_sub).

    ``out.proj`` (n_steps, m) or (0, m) = not recorded: the lateral momentum per unit length (N s/m)
    the inelastic projection takes from each surface node at step k, :func:`projection_impulse`.

    ``cpl.layer`` False: the paper's rigid midline (exact multipliers, then the inelastic projection);
    True: the compliant contact layer of :func:`contact_layer_ws` with per-node spring ``kc`` (m,), N/m^2,
    and dashpot ``cc`` (m,), N s/m^2; no projection (``out.proj`` stays zero). :ref:`model-contact`.

    Settled-response stop (``stop.window`` steps, 0 = off): the steps are cut into windows of
    ``stop.window``; a window is quiet when the glottal width varied by at most ``stop.width`` (m) over it,
    the largest nodal speed in it is at most ``stop.vel`` (m/s) and no larger than in the window before.
    After two quiet windows in a row the response has settled: the run stops, every per-step output of
    the remaining steps repeats the last step's (trajectories the last state), and ``out.stop[0]`` gets
    the step (0 = ran to the end). :ref:`model-numerics-stopping-settled-simulations`.
    """
    n = st.u.size
    m = pat.sdx.size
    nmod = cpl.sub_coef.shape[0]
    ws = Work(
        np.empty(n),
        np.empty(n),
        np.empty(n),
        np.empty(n),
        np.empty(m),
        np.empty(m),
        np.empty(m),
        np.empty(m),
        np.empty(m),
        np.empty(m),
        np.empty(m),
        np.zeros(m, dtype=np.bool_),
        np.empty((m, m)),
        np.empty(m),
        np.empty(m, dtype=np.int64),
        np.empty(m),
        np.empty(m),
        np.zeros(nmod),
        np.zeros(nmod),
    )
    return integrate_ws(stp, pat, mod, cpl, stop, mat, st, out, ws)


@njit(cache=True)
def integrate_ws(stp, pat, mod, cpl, stop, mat, st, out, ws):
    """:func:`integrate_coupled` with caller-owned work arrays ``ws`` (a :class:`._args.Work`; sub_p1, sub_p2
    are zeroed here). Every array may be a strided view.

    It allocates nothing and assigns no slices, so numba's CUDA target compiles it as a device function:
    :mod:`vfcore.solver._cuda_kernels` runs it once per GPU thread on the sample's columns of interleaved
    ``[entry, sample]`` arrays, the same arithmetic as the scalar kernel.
    """
    n_steps, h, am, af, beta, gamma = stp
    indptr, indices, Lp, Lj, sdx, sdz, sX, sZ = pat
    p_sub, p_sup, sep_ratio, x_mid, closed_tol, g_reg, flow, blowup = mod
    sub_coef, flow_coef, layer, kc, cc = cpl
    stop_window, stop_width, stop_vel = stop
    kval, mval, dval, Lx, G = mat
    u, v, a = st
    width, gsep_out, lam_out, proj_out, p_in_out, traj_every, traj_u, traj_v, stop_out = out
    (y1, y2, r, ws_u0, xs, zs, gap, fx, fz, pres, lam, active, ws_S, ws_rhs, ws_idx, ws_keff, ws_bb, sub_p1, sub_p2) = (
        ws
    )
    n = u.size
    m = sdx.size
    c0, c2, c3, m_v, m_a, d_v, d_a, lam_scale = step_coefficients(h, am, af, beta, gamma)
    wl = 1.0 - af
    ntr = 0
    nmod = sub_coef.shape[0]
    for i in range(nmod):
        sub_p1[i] = 0.0
        sub_p2[i] = 0.0
    for j in range(m):
        active[j] = False
    q1 = 0.0
    q2 = 0.0
    p_in = p_sub
    win_v = 0.0
    win_hi = -np.inf
    win_lo = np.inf
    prev_v = np.inf
    prev_quiet = False
    for k in range(1, n_steps + 1):
        for j in range(m):
            if sdx[j] >= 0:
                xs[j] = sX[j] + u[sdx[j]]
                zs[j] = sZ[j] + u[sdz[j]]
            else:
                xs[j] = sX[j]
                zs[j] = sZ[j]
            gap[j] = x_mid - xs[j]
        surface_loads(xs, zs, sX, sZ, gap, p_in, p_sup, sep_ratio, closed_tol, g_reg, fx, fz, pres, flow)
        for i in range(n):
            y1[i] = m_v * v[i] + m_a * a[i]
            y2[i] = d_v * v[i] + d_a * a[i]
        for i in range(n):
            s = 0.0
            for p in range(indptr[i], indptr[i + 1]):
                j = indices[p]
                s += mval[p] * y1[j] + dval[p] * y2[j] - kval[p] * u[j]
            r[i] = s
        for j in range(m):
            if sdx[j] >= 0:
                r[sdx[j]] += fx[j]
                r[sdz[j]] += fz[j]
        chol_solve(Lp, Lj, Lx, r)
        for i in range(n):
            r[i] += u[i]  # r is now u_{n+1} before contact
        if layer:
            settled = contact_layer_ws(
                r, u, h, wl, sdx, sX, x_mid, G, kc, cc, lam, active, 50, ws_u0, ws_S, ws_rhs, ws_idx, ws_keff, ws_bb
            )
        else:
            settled = contact_correct_ws(r, sdx, sX, x_mid, G, lam, active, 50, ws_u0, ws_S, ws_rhs, ws_idx)
        if settled < 0:
            return -k  # contact active set did not settle: a failure, never silent penetration
        bad = False
        for i in range(n):
            du = r[i] - u[i]
            an = c0 * du - c2 * v[i] - c3 * a[i]
            v[i] = v[i] + h * ((1.0 - gamma) * a[i] + gamma * an)
            a[i] = an
            u[i] = r[i]
            if not (abs(u[i]) < blowup):
                bad = True
        if bad:
            return k
        # inelastic impact: a node held at the midline keeps no normal velocity or
        # acceleration (the trapezoidal rule would otherwise bounce it back every step)
        rec = proj_out.shape[0] > 0
        for j in range(m):
            if active[j] and not layer:
                if rec:
                    proj_out[k - 1, j] = projection_impulse(indptr, mval, sdx[j], v[sdx[j]], a[sdx[j]], h, gamma)
                v[sdx[j]] = 0.0
                a[sdx[j]] = 0.0
        gmin = 1e300
        for j in range(m):
            xj = sX[j] + (u[sdx[j]] if sdx[j] >= 0 else 0.0)
            g = x_mid - xj
            if g < gmin:
                gmin = g
            lam_out[k - 1, j] = -lam[j] * lam_scale
        width[k - 1] = 2.0 * (gmin if gmin > 0.0 else 0.0)
        gsep_out[k - 1] = sep_ratio * gmin if gmin > closed_tol else 0.0
        if nmod > 0:
            dpq = p_in - p_sup
            q = flow_coef * gsep_out[k - 1] * math.sqrt(dpq) if dpq > 0.0 else 0.0
            p_in = p_sub - subglottal_step(sub_coef, sub_p1, sub_p2, q, q2)
            q2 = q1
            q1 = q
            p_in_out[k - 1] = p_in
        if traj_every > 0 and k % traj_every == 0 and ntr < traj_u.shape[0]:
            for i in range(n):
                traj_u[ntr, i] = u[i]
                traj_v[ntr, i] = v[i]
            ntr += 1
        if stop_window > 0:
            vm = 0.0
            for i in range(n):
                av = abs(v[i])
                vm = av if av > vm else vm
            if vm > win_v:
                win_v = vm
            wk = width[k - 1]
            if wk > win_hi:
                win_hi = wk
            if wk < win_lo:
                win_lo = wk
            if k % stop_window == 0:
                quiet = win_hi - win_lo <= stop_width and win_v <= stop_vel and win_v <= prev_v
                if quiet and prev_quiet:
                    stop_out[0] = k
                    for kk in range(k, n_steps):
                        width[kk] = width[k - 1]
                        gsep_out[kk] = gsep_out[k - 1]
                        for j in range(m):
                            lam_out[kk, j] = lam_out[k - 1, j]
                            if rec:
                                proj_out[kk, j] = proj_out[k - 1, j]
                        if nmod > 0:
                            p_in_out[kk] = p_in_out[k - 1]
                    if traj_every > 0:
                        for t in range(ntr, traj_u.shape[0]):
                            for i in range(n):
                                traj_u[t, i] = u[i]
                                traj_v[t, i] = v[i]
                    return 0
                prev_quiet = quiet
                prev_v = win_v
                win_v = 0.0
                win_hi = -np.inf
                win_lo = np.inf
    return 0
