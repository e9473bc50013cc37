"""Forward model (vfcore.forward) against physics: energy balance of the integrator,
self-sustained oscillation at Table 3, contact admissibility, convergence, failure modes."""

import math
from functools import cache

import numpy as np
import pytest

from vfcore import TABLE3, Params, SimConfig, simulate, simulate_batch
from vfcore import forward as fw
from vfcore.solver import _args as A
from vfcore.solver import _kernels as kern
from vfcore.solver.system import get_system

RANGE_F0 = (60.0, 250.0)
RANGE_PEAK = (2.0, 30.0)


@cache
def _sim(mesh="medium", dt=5e-5, x0=8.4, keep=False):
    return simulate(TABLE3.replace(x0=x0), SimConfig(mesh=mesh, dt=dt, keep_trajectories=keep))


# ---------------------------------------------------------------- (a) energy balance
def _free_vibration(eta_si, rho_inf=1.0, n_steps=1500, h=5e-5):
    """Undriven (p_sub = 0), contact-free (midline 1 m away) vibration from a static deflection."""
    s = get_system("medium", 0.4995)
    si = TABLE3.si()
    K_vals = s.stiffness_values((si["E_body"], si["E_lig"], si["E_cover"]))
    m_vals = si["rho"] * s.m_vals
    d_vals = eta_si * s.d_vals
    K, M, D = s.matrix(K_vals), s.matrix(m_vals), s.matrix(d_vals)
    # initial state: static deflection under a 500-Pa-like lateral surface load
    f = np.zeros(s.n)
    w = s.mesh.surface_weights()
    for j in range(s.sdx.size):
        if s.sdx[j] >= 0:
            f[s.sdx[j]] = -500.0 * w[j]
    u = f.copy()
    s.solve(s.factor(K_vals), u)
    v = np.zeros(s.n)
    a = -(K @ u)  # consistent: M a0 = -K u0 - D v0
    s.solve(s.factor(m_vals), a)
    cM, cD, cK = kern.effective_scales(h, rho_inf)
    Lx = s.factor(cK * K_vals + cD * d_vals + cM * m_vals)
    G = s.contact_columns(Lx)
    am, af, beta, gamma = kern.newmark_coefficients(h, rho_inf)
    m = s.sdx.size
    tu, tv = np.zeros((n_steps, s.n)), np.zeros((n_steps, s.n))
    u0, v0 = u.copy(), v.copy()
    st = kern.integrate(
        A.Stepper(n_steps, h, am, af, beta, gamma),
        A.Pattern(s.indptr, s.indices, s.Lp, s.Lj, s.sdx, s.sdz, s.sX, s.sZ),
        A.Model(0.0, 0.0, 1.3, 1.0, fw.CLOSED_TOL, 0.0, 0, fw.BLOWUP),
        A.Matrices(K_vals, m_vals, d_vals, Lx, G),
        A.State(u, v, a),
        A.Outputs(
            np.zeros(n_steps),
            np.zeros(n_steps),
            np.zeros((n_steps, m)),
            np.zeros((0, m)),
            np.zeros(0),
            1,
            tu,
            tv,
            np.zeros(1, dtype=np.int64),
        ),
    )
    assert st == 0
    U = np.vstack([u0, tu])
    V = np.vstack([v0, tv])
    energy = 0.5 * np.einsum("ij,ij->i", V, (M @ V.T).T) + 0.5 * np.einsum("ij,ij->i", U, (K @ U.T).T)
    power = np.einsum("ij,ij->i", V, (D @ V.T).T)
    Vm = 0.5 * (V[1:] + V[:-1])
    power_mid = np.einsum("ij,ij->i", Vm, (D @ Vm.T).T)
    return energy, power, power_mid, h, U


def test_newmark_conserves_energy_undamped():
    energy, _, _, _, U = _free_vibration(eta_si=1e-12)
    assert np.abs(U).max() > 1e-5  # it really moves (tens of micrometres)
    drift = np.abs(energy - energy[0]).max() / energy[0]
    print("relative energy drift", drift)
    assert drift < 1e-8


def test_damped_energy_decays_by_the_dissipated_work():
    energy, power, power_mid, h, _ = _free_vibration(eta_si=TABLE3.si()["eta"])
    assert np.all(np.diff(energy) <= 1e-12 * energy[0])  # monotone
    lost = energy[0] - energy[-1]
    assert lost > 0.05 * energy[0]  # damping is significant over the run
    # trapezoid of the dissipated power
    work = h * (0.5 * power[0] + power[1:-1].sum() + 0.5 * power[-1])
    assert work == pytest.approx(lost, rel=0.03)
    # the exact discrete identity of the trapezoidal rule: dE = -h v_{n+1/2}' D v_{n+1/2}
    np.testing.assert_allclose(np.diff(energy), -h * power_mid, rtol=1e-6, atol=1e-10 * energy[0])


def test_generalised_alpha_dissipates_undamped_energy():
    energy, _, _, _, _ = _free_vibration(eta_si=1e-12, rho_inf=0.5)
    assert energy[-1] < energy[0] * (1 - 1e-4)
    assert energy.max() <= energy[0] * 1.05


# ---------------------------------------------------------------- (b), (c) limit cycle
def _check_oscillation(r):
    assert r.ok, r.message
    assert RANGE_F0[0] <= r.f0 <= RANGE_F0[1], r.f0
    pk = r.cycles.peak_area
    assert pk.size >= 10
    assert RANGE_PEAK[0] <= pk.mean() <= RANGE_PEAK[1], pk.mean()
    assert np.all(np.isfinite(r.gaw)) and r.gaw.min() >= 0.0


def test_table3_limit_cycle_medium():
    r = _sim()
    _check_oscillation(r)
    cyc = r.cycles
    last = cyc.t_start >= (r.config.duration - r.config.discard) - 0.1
    assert last.sum() >= 4
    pk = cyc.peak_area[last]
    cv = pk.std() / pk.mean()
    print("f0", r.f0, "peak", pk.mean(), "cv(last 100 ms)", cv)
    assert cv < 0.02
    # the glottis closes every cycle (collision, Table 3 is a closing configuration)
    assert np.all(cyc.min_area < 0.05 * cyc.peak_area)
    # the camera-rate series agree with the cycle summaries
    assert r.gaw.max() == pytest.approx(cyc.peak_area.max(), rel=0.05)


@pytest.mark.parametrize(
    "mesh",
    [
        "coarse",
        "medium",
        pytest.param(
            "fine",
            marks=pytest.mark.xfail(
                reason="fine mesh at Table 3: f0 ~58.7 Hz (< 60) and a small non-closing cycle (~2.2-2.6 mm^2) "
                "-- amplitude is not mesh-converged (coarse 19, medium 27, fine 2.4 mm^2); with the locking-free "
                "element='anp' all three oscillate (test_element_option.py)",
                strict=False,
            ),
        ),
    ],
)
def test_all_meshes_oscillate(mesh):
    _check_oscillation(_sim(mesh=mesh))


# ---------------------------------------------------------------- (d) contact admissibility
def test_contact_never_violated_and_pressure_when_closed():
    r = _sim(keep=True)
    assert r.ok
    mesh = get_system("medium", r.config.nu).mesh
    xs = mesh.points[mesh.surface, 0] * 1e3 + r.trajectories[:, mesh.surface, 0]  # mm
    x_mid = TABLE3.x0 + r.config.half_gap_mm
    assert xs.max() <= x_mid + 1e-9
    assert np.all(r.contact_pressure >= 0.0) and np.all(r.contact_force >= 0.0)
    closed = r.gaw <= 0.0
    opened = r.gaw > 0.05 * r.gaw.max()
    assert closed.sum() >= 20 and opened.sum() >= 20
    assert np.all(r.contact_pressure[closed].max(axis=1) > 0.0)
    assert np.all(r.contact_pressure[opened].max(axis=1) == 0.0)
    # the node closest to the midline in a closed frame touches it
    assert np.all(np.abs(xs[closed].max(axis=1) - x_mid) < 1e-9)


# ---------------------------------------------------------------- (e) time-step convergence
def test_time_step_convergence_of_transient_waveform():
    """The GAW over the first 10 ms (before the first collisions dominate) converges in dt."""
    dts = [1e-4, 5e-5, 2.5e-5]
    g = [simulate(TABLE3, SimConfig(dt=dt, duration=0.01, discard=0.0, fps=10000)).gaw for dt in dts]
    d = [np.abs(g[i] - g[i + 1]).max() for i in range(len(g) - 1)]
    order = math.log2(d[0] / d[1])
    print("transient GAW differences", d, "observed order", order)
    assert d[1] < d[0]
    assert order > 0.8


@pytest.mark.xfail(
    reason="limit-cycle f0 / mean peak area are not monotonically convergent in dt "
    "(measured: f0 64.19, 64.11, 64.07, 64.21 Hz; peak 27.63, 26.47, 25.95, 26.26 mm^2 at "
    "dt = 1e-4 .. 1.25e-5): contact events / ~1 % cycle-to-cycle variation dominate",
    strict=False,
)
def test_time_step_convergence_of_limit_cycle():
    dts = [1e-4, 5e-5, 2.5e-5, 1.25e-5]
    rs = [_sim(dt=dt) for dt in dts]
    f0 = np.array([r.f0 for r in rs])
    pk = np.array([r.cycles.peak_area.mean() for r in rs])
    for name, q in (("f0", f0), ("peak", pk)):
        d = np.abs(np.diff(q))
        orders = np.log2(d[:-1] / d[1:])
        print(name, q, "differences", d, "orders", orders)
        assert np.all(np.diff(d) < 0)
        assert orders.min() > 0.8


# ---------------------------------------------------------------- (f) validation
@pytest.mark.parametrize(
    "kw,name",
    [
        (dict(E_body=0.0), "E_body"),
        (dict(E_body=-1.0), "E_body"),
        (dict(E_cover=float("nan")), "E_cover"),
        (dict(x0=8.5), "x0"),
        (dict(x0=-0.1), "x0"),
        (dict(eta=0.0), "eta"),
        (dict(rho=float("inf")), "rho"),
        (dict(p_sub=-5.0), "p_sub"),
    ],
)
def test_invalid_parameters_raise(kw, name):
    with pytest.raises(ValueError, match=name):
        simulate(TABLE3.as_dict() | kw)
    with pytest.raises(ValueError, match=name):
        TABLE3.replace(**kw)


@pytest.mark.parametrize("nu", [0.5, 0.7, -1.0, float("nan")])
def test_invalid_nu_raises(nu):
    with pytest.raises(ValueError, match="nu"):
        SimConfig(nu=nu)


def test_invalid_array_shape_raises():
    with pytest.raises(ValueError):
        simulate(np.ones(6))
    with pytest.raises(ValueError):
        simulate_batch(np.ones((3, 6)))


# ---------------------------------------------------------------- (g) blow-up
def test_blow_up_reported_not_nan():
    # nearly no stiffness and a high lung pressure: the fold is blown laterally beyond 1 cm
    p = Params(E_body=0.01, E_cover=1.0, E_lig=0.01, p_sub=5000.0, rho=1051.0, eta=0.01, x0=8.4)
    r = simulate(p, SimConfig(duration=0.05, discard=0.01))
    assert r.ok is False
    assert "diverged" in r.message
    assert r.gaw.size == 0 and r.t.size == 0 and r.flow.size == 0
    assert math.isnan(r.f0)


# ---------------------------------------------------------------- (h), (i) reproducibility
def test_bit_identical_reruns():
    a = simulate(TABLE3, SimConfig(duration=0.1, discard=0.05))
    b = simulate(TABLE3, SimConfig(duration=0.1, discard=0.05))
    for f in ("gaw", "width", "flow", "contact_pressure", "contact_force"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))


def test_batch_parallel_equals_serial():
    cfg = SimConfig(duration=0.1, discard=0.05)
    P = np.array([TABLE3.as_array(), TABLE3.replace(p_sub=800.0).as_array(), TABLE3.replace(E_cover=900.0).as_array()])
    ser = simulate_batch(P, cfg, n_workers=1)
    par = simulate_batch(P, cfg, n_workers=2)
    assert len(ser) == len(par) == 3
    for a, b in zip(ser, par):
        assert a.ok and b.ok
        np.testing.assert_array_equal(a.gaw, b.gaw)
        np.testing.assert_array_equal(a.contact_force, b.contact_force)
    assert not np.array_equal(ser[0].gaw, ser[1].gaw)


# ---------------------------------------------------------------- (j) medial compression
def test_medial_compression_prestress():
    s = get_system("medium", 0.4995)
    cfg = SimConfig()
    forces = {}
    for x0 in (8.4, 8.3, 8.2):
        p = TABLE3.replace(x0=x0)
        si = p.si()
        K_vals = s.stiffness_values((si["E_body"], si["E_lig"], si["E_cover"]))
        x_mid = fw.midline(p, cfg)
        u, lam = fw.prestress(s, K_vals, x_mid)
        xs = s.sX + np.where(s.sdx >= 0, u[np.maximum(s.sdx, 0)], 0.0)
        assert xs.max() <= x_mid * (1 + 1e-12)
        assert np.all(lam >= 0)
        forces[x0] = lam.sum()
    assert forces[8.4] == 0.0
    assert 0 < forces[8.3] < forces[8.2]
    r0, r1 = _sim(), _sim(x0=8.3)
    assert r1.ok
    assert r1.f0 != pytest.approx(r0.f0, rel=1e-3)
    assert r1.cycles.peak_area.mean() < r0.cycles.peak_area.mean()


# ---------------------------------------------------------------- (k) flow
def test_flow_is_bernoulli_jet_of_the_minimum_area():
    r = _sim()
    dp = TABLE3.p_sub - r.config.p_sup
    q = r.config.sep_ratio * r.gaw * 1e-6 * math.sqrt(2 * dp / fw.RHO_AIR)
    open_ = r.gaw > 1e-3
    assert open_.sum() > 100
    np.testing.assert_allclose(r.flow[open_], q[open_], rtol=1e-9)
    assert np.all(r.flow[r.gaw <= 0] == 0.0)
    # order of magnitude: peak flow of a ~27 mm^2 glottis at ~1 kPa is a few hundred ml/s
    assert 1e-4 < r.flow.max() < 2e-3


def test_config_differences_name_what_changes_the_simulation():
    """``SimConfig.differences`` (what ``diagnose --base`` checks): a record read back from JSON equals its config;
    a changed step or law is named with both values; settings that do not change the waveform, the layer's
    thickness under the rigid projection, and settings an older record lacks are not differences."""
    import json

    cfg = SimConfig(mesh="coarse", dt=1e-4, fps=2000.0, epithelium_profile=(1.0,) * 20 + (2.0,))
    rec = json.loads(json.dumps(cfg.as_dict()))
    assert cfg.differences(rec) == {}
    assert cfg.differences({**rec, "dt": 5e-5, "mesh": "medium"}) == {"dt": (5e-5, 1e-4), "mesh": ("medium", "coarse")}
    assert cfg.differences({**rec, "early_stop": False, "keep_trajectories": True}) == {}
    assert cfg.differences({**rec, "contact_layer_mm": 0.3}) == {}  # projection: no layer
    layer = cfg.replace(contact="layer")
    assert layer.differences({**rec, "contact": "layer", "contact_layer_mm": 0.3}) == {"contact_layer_mm": (0.3, 0.1)}
    assert layer.differences(rec) == {"contact": ("projection", "layer")}
    assert cfg.differences({k: v for k, v in rec.items() if k != "contact"}) == {}
    assert cfg.differences({**rec, "epithelium_profile": [1.0] * 21}) == {
        "epithelium_profile": ([1.0] * 21, [1.0] * 20 + [2.0])
    }
