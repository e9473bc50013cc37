"""The continuous flow load: the paper's Bernoulli / closed-glottis physics with every switch resolved between nodes.

The paper's rule (:func:`._kernels.surface_loads` with ``flow = FLOW_PAPER``) gives each surface node a pressure
and lumps it by halves onto the two edges beside it. Its nodal pressures switch with discrete states: which node
is the narrowest, where the flow separates when the gap widens past ``sep_ratio * g_min`` and narrows again
behind, which node closed first. Each switch moves a pressure between p_sub, a Bernoulli value and p_sup at once,
so the load, and through it the waveform and the log-likelihood, jumps between neighbouring parameter values.

Here every nodal pressure is a continuous function of the nodes' signed half gaps (negative while a node overlaps
the midline), and the lumping by halves stays the paper's:

- **the narrowest node**: each node within ``MIN_BLEND * g_min`` of the narrowest is weighted in as the node the
  flow separates behind (weight ``1 - w((g_k - g_min) / (MIN_BLEND g_min))``, normalised), and each candidate k
  gives the paper's distribution: upstream of k the paper's near-closure blend ``w_c Bern + (1 - w_c) p_sub``,
  ``w_c = w(g_min / g_reg)``; from k on the Bernoulli value;
- **attachment downstream of k**: the Bernoulli deficit ``q = dp (1 - (g_sep / g)^2)``, ``g_sep = sep_ratio *
  g_min``, clipped at 0 (a node at or past ``g_sep`` has p_sup: the paper's separation, which is continuous in the
  nodal values) and weighted by ``1 - w((G - g_sep) / (ZETA g_sep))``, G the largest gap between k and the node: a
  narrowing behind a ridge past ``(1 + ZETA) g_sep`` is separated, one behind a lower ridge attached in proportion,
  so a ridge sinking through ``g_sep`` no longer switches a whole stretch from p_sup to Bernoulli suction;
- **closed** (``g_min <= 0``): p_sub upstream of the first node at or past the midline, p_sup from it on;
- **near a closure**: every node's pressure above p_sup is multiplied by ``w(R / g_reg)``, R the narrowest gap up to
  and including that node, so a node nearing the midline, and every node behind it, fades to p_sup before it
  closes: the closure front moving upstream, or a second closure upstream of the first, moves no pressure at once;
  downstream of the narrowest node the factor is ``w_c``, the paper's blend weight.

``w(s) = s^2 (3 - 2 s)`` on [0, 1]. When the glottis is open wider than ``g_reg`` with one narrowest node and no
narrowing behind the separation, every weight is 0 or 1 and the load equals the paper's to rounding. :ref:`continuous-model`.
"""

from __future__ import annotations

from numba import njit

#: Relative width of the blend between near-equal local minima of the gap (as a fraction of g_min).
MIN_BLEND = 0.1
#: Relative width of the partial attachment behind a ridge just above g_sep (as a fraction of g_sep).
ZETA = 0.1


@njit(cache=True)
def smoothstep(s):
    """``s^2 (3 - 2 s)`` on [0, 1], 0 below, 1 above: C^1, monotone."""
    if s <= 0.0:
        return 0.0
    if s >= 1.0:
        return 1.0
    return s * s * (3.0 - 2.0 * s)


@njit(cache=True)
def lump_pressures(nxs, nzs, pres, fx, fz):
    """Nodal forces (N/m, into the fold) of the nodal pressures ``pres`` (m,), Pa: each node's pressure acts on
    the halves of its two edges (the paper's lumping), along the inward normal rot90(e) = (-ez, ex) of the
    reference edges ``nxs``, ``nzs``. Writes ``fx``, ``fz`` (m,)."""
    m = pres.size
    for i in range(m):
        fx[i] = 0.0
        fz[i] = 0.0
    for i in range(m - 1):
        ex = nxs[i + 1] - nxs[i]
        ez = nzs[i + 1] - nzs[i]
        fx[i] += 0.5 * pres[i] * (-ez)
        fz[i] += 0.5 * pres[i] * ex
        fx[i + 1] += 0.5 * pres[i + 1] * (-ez)
        fz[i + 1] += 0.5 * pres[i + 1] * ex


@njit(cache=True)
def _min_weight(gap, k, gmin):
    """Weight of node k as the node the flow separates behind: 1 at the narrowest node, falling to 0 for a node
    ``MIN_BLEND * gmin`` wider."""
    return 1.0 - smoothstep((gap[k] - gmin) / (MIN_BLEND * gmin))


@njit(cache=True)
def surface_loads_continuous(xs, zs, nxs, nzs, gap, p_sub, p_sup, sep_ratio, g_reg, fx, fz, pres):
    """Continuous Bernoulli / closed-glottis surface load (see the module docstring).

    xs, zs : (m,) current surface coordinates (inferior -> superior), m (unused: the small-strain load acts on
        the reference edges; kept for the paper rule's signature).
    nxs, nzs : (m,) reference coordinates whose edges give the load directions, m.
    gap : (m,) signed half gap to the midline, m (negative while a node overlaps it).
    g_reg : near-closure scale, m (0 = no blend: the paper's hard switch, a node fades only once closed).
    fx, fz : (m,) nodal forces per unit depth, N/m, into the fold (written). pres : (m,) nodal pressures, Pa
        (written).
    Returns (min half gap clamped at 0, half gap at separation (0 when closed), the first node at or past the
    midline or -1).
    """
    m = gap.size
    imin = 0
    for i in range(m):
        if gap[i] < gap[imin]:
            imin = i
    gmin = gap[imin]
    dp = p_sub - p_sup
    for i in range(m):
        pres[i] = 0.0  # p - p_sup, accumulated
    iclose = -1
    gsep = 0.0
    if gmin <= 0.0:
        jc = 0
        while gap[jc] > 0.0:
            jc += 1
        iclose = jc
        for i in range(jc):
            pres[i] = dp
    else:
        gsep = sep_ratio * gmin
        w = smoothstep(gmin / g_reg) if g_reg > 0.0 else 1.0
        wsum = 0.0
        for k in range(m):
            wsum += _min_weight(gap, k, gmin)
        for k in range(m):
            wk = _min_weight(gap, k, gmin)
            if wk <= 0.0:
                continue
            wk /= wsum
            # upstream of the narrowest node: the paper's blend of Bernoulli and p_sub
            for i in range(k):
                r = gsep / gap[i]
                pres[i] += wk * (w * dp * (1.0 - r * r) + (1.0 - w) * dp)
            # from it on: the attached Bernoulli deficit (its near-closure fade is the factor below)
            ridge = gap[k]
            for i in range(k, m):
                g = gap[i]
                if g > ridge:
                    ridge = g
                att = 1.0 - smoothstep((ridge - gsep) / (ZETA * gsep))
                if att <= 0.0:
                    break
                r = gsep / g
                q = dp * (1.0 - r * r)
                if q < 0.0:
                    pres[i] += wk * att * q
    # the narrowest gap up to and including a node: a node at, behind or in a near-closure fades to p_sup
    rmin = gap[0]
    for i in range(m):
        if gap[i] < rmin:
            rmin = gap[i]
        if rmin < g_reg or rmin <= 0.0:
            pres[i] *= smoothstep(rmin / g_reg) if g_reg > 0.0 else 0.0
    for i in range(m):
        pres[i] += p_sup
    lump_pressures(nxs, nzs, pres, fx, fz)
    return (gmin if gmin > 0.0 else 0.0), gsep, iclose
