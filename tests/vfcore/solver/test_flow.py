"""The continuous flow load (:mod:`vfcore.solver._flow`): continuity in the surface positions, and agreement with
the paper's rule where no switch is near.

The continuity checks bisect the largest change of the nodal forces along a line of surface positions: a
Lipschitz load's change halves with the step, a jump keeps its size however small the step.
"""

from __future__ import annotations

import numpy as np
import pytest

from vfcore.solver import _kernels as kern

MM = 1e-3
P_SUB, P_SUP, SEP, G_REG = 1000.0, 0.0, 1.3, 0.02 * MM


def forces(gap, flow, nz=None, g_reg=G_REG, p_sup=P_SUP):
    m = len(gap)
    nz = np.linspace(0.0, 1e-2, m) if nz is None else nz
    nx = np.full(m, 8.4e-3)
    fx, fz, pres = np.zeros(m), np.zeros(m), np.zeros(m)
    out = kern.surface_loads(
        nx - gap, nz, nx, nz, np.array(gap, float), P_SUB, p_sup, SEP, 1e-9, g_reg, fx, fz, pres, flow
    )
    return np.r_[fx, fz], out, pres


def largest_jump(gap, d, flow, span=2e-6, n=101, halvings=24, nz=None):
    """Scan gap + x d over |x| <= span, take the neighbours with the largest force change and bisect towards
    it ``halvings`` times. Returns (change on the scan's step, change on the final step), N/m."""
    xs = np.linspace(-span, span, n)
    F = np.array([forces(gap + x * d, flow, nz)[0] for x in xs])
    dif = np.linalg.norm(np.diff(F, axis=0), axis=1)
    k = int(np.argmax(dif))
    a, b, Fa, Fb = xs[k], xs[k + 1], F[k], F[k + 1]
    for _ in range(halvings):
        c = 0.5 * (a + b)
        Fc = forces(gap + c * d, flow, nz)[0]
        if np.linalg.norm(Fc - Fa) >= np.linalg.norm(Fb - Fc):
            b, Fb = c, Fc
        else:
            a, Fa = c, Fc
    return dif[k], float(np.linalg.norm(Fb - Fa))


def is_jump(first, last):
    # 24 halvings shrink a Lipschitz change 1.7e7-fold; a jump keeps it
    return last > 1e-3 * first and last > 1e-9


def random_profile(rng, kind, m):
    t = np.linspace(-1.0, 1.0, m)
    if kind == "one minimum":  # open or closed, separation anywhere along an edge
        c = rng.uniform(-0.5, 0.5)
        return (rng.uniform(-0.05, 0.3) + rng.uniform(0.2, 2.0) * (t - c) ** 2) * MM
    if kind == "two closures":  # two narrow places, either or both at the midline: pockets
        return (np.abs(np.sin(3.0 * t + rng.uniform(0, 6))) * rng.uniform(0.01, 0.5) + rng.uniform(-0.05, 0.05)) * MM
    if kind == "two minima":  # two near-equal narrowest points
        return (np.minimum((t - 0.5) ** 2, (t + 0.3) ** 2 + rng.uniform(-0.02, 0.02)) + rng.uniform(-0.03, 0.05)) * MM
    return rng.uniform(-0.05, 0.3, m) * MM  # rough


KINDS = ("one minimum", "two closures", "two minima", "rough")


@pytest.mark.parametrize("kind", KINDS)
def test_continuous_load_is_lipschitz_on_random_profiles(kind):
    rng = np.random.default_rng(sum(map(ord, kind)))
    for _ in range(60):
        m = int(rng.integers(5, 25))
        gap = random_profile(rng, kind, m)
        d = rng.normal(size=m)
        d /= np.linalg.norm(d)
        first, last = largest_jump(gap, d, kern.FLOW_CONTINUOUS)
        assert not is_jump(first, last), (kind, gap / MM, d)


def test_paper_rule_jumps_on_the_same_profiles():
    """The check above can fail: on the same families the paper's node-wise rule jumps."""
    rng = np.random.default_rng(7)
    jumps = 0
    for kind in KINDS:
        for _ in range(40):
            m = int(rng.integers(5, 25))
            gap = random_profile(rng, kind, m)
            d = rng.normal(size=m)
            d /= np.linalg.norm(d)
            jumps += is_jump(*largest_jump(gap, d, kern.FLOW_PAPER))
    assert jumps >= 1


def _one_node(m, i, amount):
    d = np.zeros(m)
    d[i] = amount
    return d


# switches of the paper's rule, each crossed by moving one node's gap
SWITCHES = {
    # node 6's gap (1.3 mm + 10 nm) sinks through g_sep = 1.3 mm with a narrowing behind it: separation jumps to node 8
    "a ridge behind separation sinks through g_sep": (np.array([5, 4, 3, 2, 1, 1.2, 1.30001, 1.25, 1.5, 2]) * MM, 6),
    # two narrow places 0.5 mm apart with a wide valley between trade places as the narrowest
    "two separated minima trade places": (np.array([0.5, 0.3, 0.1, 0.3, 0.5, 0.3, 0.1, 0.3, 0.5]) * MM, 6),
    # nodes 3 and 4 tie as the narrowest, nearer the midline than g_reg: where the closure blend puts p_sub
    "the narrowest node changes near closure": (np.array([0.48, 0.24, 0.08, 0.0026, 0.0026, 0.08, 0.25]) * MM, 3),
    # closed at node 6; node 2, upstream behind a widening, touches too: a second closure
    "a second closure upstream": (np.array([0.4, 0.1, 0.0, 0.2, 0.3, 0.1, -0.01, 0.1, 0.3]) * MM, 2),
    # closed at node 5; node 4 just above the midline touches: the closure front moves upstream
    "the closure front moves upstream": (np.array([0.5, 0.3, 0.17, 0.06, 0.0, -0.02, 0.0006, 0.06]) * MM, 4),
}


@pytest.mark.parametrize("case", list(SWITCHES))
def test_each_paper_switch_is_continuous_in_the_new_load(case):
    gap, i = SWITCHES[case]
    d = _one_node(gap.size, i, 1.0)
    first, last = largest_jump(gap, d, kern.FLOW_CONTINUOUS, span=2e-8)
    assert not is_jump(first, last)
    first_p, last_p = largest_jump(gap, d, kern.FLOW_PAPER, span=2e-8)
    assert is_jump(first_p, last_p), "the paper's rule should switch here"


def test_continuous_through_the_first_closure():
    """The narrowest node touches the midline: open -> closed (continuous in both rules with g_reg > 0)."""
    gap = np.array([0.5, 0.3, 0.15, 0.06, 0.0, 0.05, 0.2, 0.4]) * MM
    first, last = largest_jump(gap, _one_node(gap.size, 4, 1.0), kern.FLOW_CONTINUOUS, span=2e-8)
    assert not is_jump(first, last)


def test_closed_glottis_pressure():
    """A straight vertical wall closed at node 4, open wider than g_reg upstream: p_sub on every node upstream
    of node 4, p_sup from it on (the paper's closed load), lumped by halves; the net force is that of p_sub on
    [0, 3.5 mm]."""
    m = 9
    nz = np.linspace(0.0, 8e-3, m)  # 1 mm edges
    gap = np.array([0.6, 0.4, 0.3, 0.1, -0.3, -0.2, 0.1, 0.3, 0.5]) * MM
    F, (gmin, gsep, iclose), pres = forces(gap, kern.FLOW_CONTINUOUS, nz=nz, p_sup=200.0)
    assert iclose == 4 and gsep == 0.0 and gmin == 0.0
    np.testing.assert_allclose(pres, [P_SUB] * 4 + [200.0] * 5, rtol=1e-14)
    wet = 3.5e-3
    assert F[:m].sum() == pytest.approx(-(P_SUB * wet + 200.0 * (8e-3 - wet)), rel=1e-12)
    assert abs(F[m:].sum()) < 1e-15


@pytest.mark.parametrize(
    "gap_mm",
    [
        [5, 4, 3, 2, 1, 1.2, 1.5, 2, 3],  # separation between nodes 5 and 6
        [5, 4, 3, 2, 1, 1.2, 1.3, 1.5, 2, 3],  # separation on node 6
        [3, 2.5, 2, 1.6, 1.3, 1.0, 0.8],  # convergent: attached to the exit
    ],
)
def test_equals_the_paper_rule_with_one_narrowest_node_open_wider_than_g_reg(gap_mm):
    """One narrowest node, no other within 10 % of it, open wider than g_reg, no narrowing behind separation:
    every blend weight is 0 or 1 and the nodal pressures are the paper's."""
    gap = np.array(gap_mm, float) * MM
    Fc, _, pc = forces(gap, kern.FLOW_CONTINUOUS)
    Fp, _, pp = forces(gap, kern.FLOW_PAPER)
    np.testing.assert_allclose(pc, pp, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(Fc, Fp, rtol=1e-12, atol=1e-12)
