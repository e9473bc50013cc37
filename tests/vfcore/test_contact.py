"""Contact: the rigid projection's and the compliant layer's laws, and the products built on them
(impulse per cycle, contact duration, pressure in contact; :ref:`model-contact`)."""

import math

import numpy as np
import pytest

from vfcore import TABLE3, SimConfig, simulate
from vfcore import forward as fw
from vfcore.solver import _args as A
from vfcore.solver import _kernels as kern


def _masses_series(mass, v0, gap, h, n_steps, kc=None, cc=None):
    """Two unconstrained point masses (no stiffness, damping or flow load) moving at v0 towards a
    midline ``gap`` away, through the production time loop: the rigid projection, or with ``kc``/``cc``
    (N/m^2, N s/m^2) the compliant layer. Returns (per-step contact force (n_steps, 2), N/m, projection
    impulses (n_steps, 2), N s/m, final u, final v)."""
    n, m = 4, 2
    indptr = np.arange(n + 1, dtype=np.int64)
    indices = np.arange(n, dtype=np.int64)
    kval, dval, mval = np.zeros(n), np.zeros(n), np.full(n, mass)
    am, af, beta, gamma = kern.newmark_coefficients(h, 1.0)
    cM, _, _ = kern.effective_scales(h, 1.0)
    Lp, Lj = indptr.copy(), indices.copy()
    Lx = np.full(n, 1.0 / np.sqrt(cM * mass))  # diagonal factor, stored as its reciprocal
    sdx = np.array([0, 2], dtype=np.int64)
    sdz = np.array([1, 3], dtype=np.int64)
    G = np.zeros((n, m))
    G[sdx, [0, 1]] = 1.0 / (cM * mass)  # K_eff^-1 e_j
    sX, sZ = np.zeros(m), np.array([0.0, 1e-3])
    u, a = np.zeros(n), np.zeros(n)
    v = np.array([v0, 0.0, v0, 0.0])
    lam, proj = np.zeros((n_steps, m)), np.zeros((n_steps, m))
    layer = kc is not None
    st = kern.integrate_coupled(
        A.Stepper(n_steps, h, am, af, beta, gamma),
        A.Pattern(indptr, indices, Lp, Lj, sdx, sdz, sX, sZ),
        A.Model(0.0, 0.0, 1.3, gap, fw.CLOSED_TOL, 0.0, 0, 1.0),
        A.Coupling(np.zeros((0, 3)), 0.0, layer, np.full(m, kc if layer else 0.0), np.full(m, cc if layer else 0.0)),
        A.Stop(0, 0.0, 0.0),
        A.Matrices(kval, mval, dval, Lx, G),
        A.State(u, v, a),
        A.Outputs(
            np.zeros(n_steps),
            np.zeros(n_steps),
            lam,
            proj,
            np.zeros(0),
            0,
            np.zeros((0, n)),
            np.zeros((0, n)),
            np.zeros(1, dtype=np.int64),
        ),
    )
    assert st == 0
    return lam, proj, u[sdx], v[sdx]


def _free_masses(mass, v0, gap, h, n_steps):
    """:func:`_masses_series` against the rigid midline: (multiplier impulse, projection impulse) per node."""
    lam, proj, u, v = _masses_series(mass, v0, gap, h, n_steps)
    assert np.allclose(u, gap, rtol=0, atol=1e-15) and np.all(v == 0.0)  # stopped at the midline
    return h * lam.sum(axis=0), proj.sum(axis=0)


@pytest.mark.parametrize("h", [1e-4, 3e-5, 1e-5])
def test_rigid_stop_impulse_is_m_v(h):
    """An inelastic stop takes exactly the momentum m v, whatever the step and wherever in a step
    the midline is reached; the multiplier's impulse alone does not (it depends on that phase)."""
    mass, v0 = 0.02, 0.7  # kg/m (per unit length), m/s
    gap = 0.37 * h * v0 + 5 * h * v0  # reached a fraction into a step
    imp_lam, imp_proj = _free_masses(mass, v0, gap, h, 20)
    np.testing.assert_allclose(imp_lam + imp_proj, mass * v0, rtol=1e-12)
    assert abs(imp_lam[0] - mass * v0) > 0.1 * mass * v0


def test_cycle_products_from_per_step_series():
    """cycle_summary: impulse = h sum f + sum projection over each cycle's steps, duration = h * steps in
    contact, pressure in contact = impulse / (h * sum of the contact lengths), for a synthetic record."""
    h = 1e-4
    t = h * np.arange(1, 2001)
    gaw = 10.0 * np.maximum(np.sin(2 * np.pi * 50.0 * t), 0.0)
    closed = gaw == 0.0
    rng = np.random.default_rng(0)
    force = np.where(closed[:, None], rng.random((t.size, 3)), 0.0)
    force[:, 1] *= rng.random(t.size) > 0.5  # node 1 touches on some steps only
    proj = np.where(closed[:, None], 1e-6 * rng.random((t.size, 3)), 0.0)
    share = np.array([1e-4, 2e-4, 3e-4])
    cyc = fw.cycle_summary(t, gaw, gaw * 0.0, force.max(axis=1), force, share, h, proj)
    assert cyc.period.size >= 3
    np.testing.assert_allclose(cyc.period, 0.02, rtol=1e-9)
    level = 5.0
    up = np.nonzero((gaw[:-1] < level) & (gaw[1:] >= level))[0]
    for i, (a, b) in enumerate(zip(up[:-1], up[1:])):
        sl = slice(a + 1, b + 1)
        imp = h * force[sl].sum() + proj[sl].sum()
        np.testing.assert_allclose(cyc.contact_impulse[i], imp, rtol=1e-12)
        assert cyc.contact_duration[i] == pytest.approx(h * closed[sl].sum(), rel=1e-12)
        ext = h * ((force[sl] > 0) * share).sum()
        np.testing.assert_allclose(cyc.contact_pressure_in_contact[i], imp / ext, rtol=1e-12)
    np.testing.assert_allclose(cyc.closed_quotient, cyc.contact_duration / cyc.period)
    # the nodal peaks stay available under their resolution-dependent names
    assert cyc.max_contact_pressure is cyc.max_contact_pressure_unconverged


def test_simulated_contact_products_consistent():
    """At Table 3 the fold closes every cycle: the products are positive, the pressure in contact
    times the contact's space-time extent is at least the multipliers' impulse read at the step rate."""
    c = SimConfig(mesh="coarse", duration=0.12, discard=0.04, fps=1.0 / 5e-5)
    r = simulate(TABLE3, c)
    y = r.cycles
    assert r.ok and y.period.size >= 3
    assert np.all(y.contact_impulse > 0) and np.all(y.contact_duration > 0)
    assert np.all(y.contact_duration < y.period)
    assert np.all((y.closed_quotient > 0) & (y.closed_quotient < 1))
    # camera rate = step rate: the camera-rate contact force is the per-step series
    f = r.contact_force.sum(axis=1)
    for ts, T, dur in zip(y.t_start, y.period, y.contact_duration):
        sel = (r.t > ts) & (r.t <= ts + T)
        assert dur == pytest.approx(c.dt * np.count_nonzero(f[sel] > 0), abs=2 * c.dt)


@pytest.mark.slow
def test_impulse_converges_in_dt():
    """The contact impulse per cycle changes less between finer steps than the nodal peak pressure
    (which grows like m v / h); measured in :ref:`model-contact`."""
    imp, pk = [], []
    for dt in (1e-4, 5e-5, 2.5e-5):
        y = simulate(TABLE3, SimConfig(dt=dt, duration=0.35, discard=0.15)).cycles
        imp.append(y.contact_impulse.mean())
        pk.append(y.max_contact_pressure_unconverged.max())
    d_imp = [abs(imp[i + 1] - imp[i]) / imp[i + 1] for i in range(2)]
    d_pk = [abs(pk[i + 1] - pk[i]) / pk[i + 1] for i in range(2)]
    assert d_imp[1] < d_imp[0]  # the differences shrink
    assert d_imp[1] < 0.15 and d_imp[1] < d_pk[1]


def _kelvin_voigt_impact(mass, v0, k, c):
    """Exact impact of a mass on a no-tension spring-dashpot layer: m x'' + c x' + k x = 0, x(0) = 0,
    x'(0) = v0 (underdamped), until the force k x + c x' returns to zero. Returns (impulse, peak force,
    duration)."""
    wn = math.sqrt(k / mass)
    z = c / (2.0 * math.sqrt(k * mass))
    wd = wn * math.sqrt(1.0 - z * z)
    t = np.linspace(0.0, math.pi / wd, 400_001)
    e = np.exp(-z * wn * t)
    x = v0 / wd * e * np.sin(wd * t)
    xd = v0 * e * (np.cos(wd * t) - z * wn / wd * np.sin(wd * t))
    f = k * x + c * xd
    end = np.nonzero(f[1:] <= 0.0)[0]
    i = end[0] + 1 if end.size else t.size - 1
    return mass * (v0 - xd[i]), f[:i].max(), t[i]


@pytest.mark.parametrize("zeta", [0.0, 0.3])
def test_layer_impact_matches_the_exact_kelvin_voigt_solution(zeta):
    """A mass hitting the compliant layer: impulse, peak force and contact duration converge to the
    exact spring-dashpot impact as the step shrinks (first order: the contact starts inside a step and
    the dashpot uses the backward difference of the overlap). zeta = 0 is the elastic bounce, impulse
    2 m v0."""
    mass, v0, k = 0.02, 0.7, 2000.0  # kg/m, m/s, N/m^2: contact of ~10 ms
    c = 2.0 * zeta * math.sqrt(k * mass)
    J, F, T = _kelvin_voigt_impact(mass, v0, k, c)
    if zeta == 0.0:
        assert J == pytest.approx(2.0 * mass * v0, rel=1e-9)
    err = []
    for h in (2e-4, 1e-4, 5e-5, 2.5e-5):
        gap = 0.37 * h * v0 + 5 * h * v0  # reached a fraction into a step
        lam, proj, _, _ = _masses_series(mass, v0, gap, h, int(round(0.03 / h)), kc=k, cc=c)
        assert np.all(proj == 0.0) and np.all(lam >= 0.0)  # no projection; never adhesive
        f = lam[:, 0]
        touching = np.nonzero(f > 0)[0]
        assert np.all(np.diff(touching) == 1)  # one contact, then free flight
        err.append((abs(h * f.sum() - J) / J, abs(f.max() - F) / F, abs(h * touching.size - T) / T))
    err = np.array(err)
    assert np.all(err[-1] < 0.02), err[-1]
    # the errors shrink about in proportion to h over the last halvings
    ratios = err[-3, :2] / err[-1, :2]
    assert np.all(ratios > 2.5), ratios


def test_layer_static_compression_is_the_spring_solution():
    """The layer's static problem (medial compression, cc = 0): a spring column under a layer of
    stiffness kc settles where the two springs share the imposed overlap, K u = -kc (u - g)."""
    n, m = 2, 1
    K = 3000.0
    kc = 1000.0
    g = 1e-4  # the midline is 0.1 mm inside the rest position
    G = np.array([[1.0 / K], [0.0]])
    u = np.zeros(n)
    lam = np.zeros(m)
    active = np.zeros(m, dtype=np.bool_)
    sdx = np.array([0], dtype=np.int64)
    it = kern.contact_layer_ws(
        u,
        np.zeros(n),
        1.0,
        1.0,
        sdx,
        np.array([g]),
        0.0,
        G,
        np.array([kc]),
        np.zeros(m),
        lam,
        active,
        20,
        np.empty(n),
        np.empty((m, m)),
        np.empty(m),
        np.empty(m, dtype=np.int64),
        np.empty(m),
        np.empty(m),
    )
    assert it >= 1
    # equilibrium: K u = f, f = -kc (g + u): u = -kc g / (K + kc)
    assert u[0] == pytest.approx(-kc * g / (K + kc), rel=1e-12)
    assert lam[0] == pytest.approx(K * u[0], rel=1e-12)


def test_layer_contact_is_an_option_of_the_config():
    with pytest.raises(ValueError, match="contact must be one of"):
        SimConfig(contact="penalty")
    with pytest.raises(ValueError, match="contact_layer_mm"):
        SimConfig(contact="layer", contact_layer_mm=0.0)


def test_layer_peak_pressure_converges_in_dt_where_the_projection_does_not():
    """Table 3, medium mesh, the two finest steps of benchmarks/bench_contact.py: with the compliant layer
    the peak nodal pressure, the impulse and the pressure in contact agree within 5 %; with the rigid
    projection the peak grows like m v / h (:ref:`model-contact`)."""

    def products(contact, dt):
        y = simulate(TABLE3, SimConfig(contact=contact, dt=dt, duration=0.35, discard=0.15)).cycles
        return np.array(
            [y.max_contact_pressure_unconverged.max(), y.contact_impulse.mean(), y.contact_pressure_in_contact.mean()]
        )

    a, b = products("layer", 1.25e-5), products("layer", 6.25e-6)
    assert np.all(np.abs(a - b) / b < 0.05), (a, b)
    pa, pb = products("projection", 1.25e-5), products("projection", 6.25e-6)
    assert pb[0] > 1.3 * pa[0]
