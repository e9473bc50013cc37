"""Contact products: impulse per cycle, contact duration, pressure in contact (docs/model.md, "Contact")."""
import numpy as np
import pytest

from vfcore import TABLE3, SimConfig, simulate
from vfcore import forward as fw
from vfcore.solver import _kernels as kern


def _free_masses(mass, v0, gap, h, n_steps):
    """Two unconstrained point masses (no stiffness, damping or flow load) moving at v0 towards a
    midline ``gap`` away, through the production time loop; returns (multiplier impulse, projection
    impulse) per node, N s/m."""
    n, m = 4, 2
    indptr = np.arange(n + 1, dtype=np.int64)
    indices = np.arange(n, dtype=np.int64)
    kval, dval, mval = np.zeros(n), np.zeros(n), np.full(n, mass)
    am, af, beta, gamma = kern.newmark_coefficients(h, 1.0)
    cM, _, _ = kern.effective_scales(h, 1.0)
    Lp, Lj = indptr.copy(), indices.copy()
    Lx = np.full(n, 1.0 / np.sqrt(cM * mass))          # diagonal factor, stored as its reciprocal
    sdx = np.array([0, 2], dtype=np.int64)
    sdz = np.array([1, 3], dtype=np.int64)
    G = np.zeros((n, m))
    G[sdx, [0, 1]] = 1.0 / (cM * mass)                 # K_eff^-1 e_j
    sX, sZ = np.zeros(m), np.array([0.0, 1e-3])
    u, a = np.zeros(n), np.zeros(n)
    v = np.array([v0, 0.0, v0, 0.0])
    lam, proj = np.zeros((n_steps, m)), np.zeros((n_steps, m))
    st = kern.integrate_coupled(n_steps, h, am, af, beta, gamma, indptr, indices, kval, mval, dval, Lp, Lj, Lx, G,
                                sdx, sdz, sX, sZ, u, v, a, 0.0, 0.0, 1.3, gap, fw.CLOSED_TOL, 0.0, 1.0,
                                np.zeros(n_steps), np.zeros(n_steps), lam, 0, np.zeros((0, n)), np.zeros((0, n)),
                                np.zeros((0, 3)), 0.0, np.zeros(0), proj)
    assert st == 0
    assert np.allclose(u[sdx], gap, rtol=0, atol=1e-15) and np.all(v[sdx] == 0.0)   # stopped at the midline
    return h * lam.sum(axis=0), proj.sum(axis=0)


@pytest.mark.parametrize("h", [1e-4, 3e-5, 1e-5])
def test_rigid_stop_impulse_is_m_v(h):
    """An inelastic stop takes exactly the momentum m v, whatever the step and wherever in a step
    the midline is reached; the multiplier's impulse alone does not (it depends on that phase)."""
    mass, v0 = 0.02, 0.7                                 # kg/m (per unit length), m/s
    gap = 0.37 * h * v0 + 5 * h * v0                    # reached a fraction into a step
    imp_lam, imp_proj = _free_masses(mass, v0, gap, h, 20)
    np.testing.assert_allclose(imp_lam + imp_proj, mass * v0, rtol=1e-12)
    assert abs(imp_lam[0] - mass * v0) > 0.1 * mass * v0


def test_cycle_products_from_per_step_series():
    """_cycles: impulse = h sum f + sum projection over each cycle's steps, duration = h * steps in
    contact, pressure in contact = impulse / (h * sum of the contact lengths), for a synthetic record."""
    h = 1e-4
    t = h * np.arange(1, 2001)
    gaw = 10.0 * np.maximum(np.sin(2 * np.pi * 50.0 * t), 0.0)
    closed = gaw == 0.0
    rng = np.random.default_rng(0)
    force = np.where(closed[:, None], rng.random((t.size, 3)), 0.0)
    force[:, 1] *= rng.random(t.size) > 0.5           # node 1 touches on some steps only
    proj = np.where(closed[:, None], 1e-6 * rng.random((t.size, 3)), 0.0)
    share = np.array([1e-4, 2e-4, 3e-4])
    cyc = fw._cycles(t, gaw, gaw * 0.0, force.max(axis=1), force, share, h, proj)
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
    (which grows like m v / h); measured in docs/model.md, "Contact"."""
    imp, pk = [], []
    for dt in (1e-4, 5e-5, 2.5e-5):
        y = simulate(TABLE3, SimConfig(dt=dt, duration=0.35, discard=0.15)).cycles
        imp.append(y.contact_impulse.mean())
        pk.append(y.max_contact_pressure_unconverged.max())
    d_imp = [abs(imp[i + 1] - imp[i]) / imp[i + 1] for i in range(2)]
    d_pk = [abs(pk[i + 1] - pk[i]) / pk[i + 1] for i in range(2)]
    assert d_imp[1] < d_imp[0]                      # the differences shrink
    assert d_imp[1] < 0.15 and d_imp[1] < d_pk[1]
