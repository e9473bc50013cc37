"""Forward-model extensions: epithelium membrane and subglottal acoustic coupling.

Both are off by default; off means bit-identical to the default model.
"""

from functools import cache

import numpy as np
import pytest
import scipy.linalg as sla

from vfcore import TABLE3, SimConfig, simulate
from vfcore.fem.assemble import membrane_unit
from vfcore.mesh import load_mesh
from vfcore.solver import _kernels as kern
from vfcore.solver.system import get_system

SHORT = dict(duration=0.12, discard=0.06)
MODE = (600.0, 0.1, 2e6)


@cache
def _sim(**kw):
    return simulate(TABLE3, SimConfig(**kw))


def _same(r1, r2):
    assert r1.ok and r2.ok
    for k in ("gaw", "gaw_hr", "width", "flow", "contact_pressure", "contact_force"):
        assert np.array_equal(getattr(r1, k), getattr(r2, k)), k


def _band_fraction(r, lo, hi):
    g = r.gaw - r.gaw.mean()
    P = np.abs(np.fft.rfft(g * np.hanning(g.size))) ** 2
    f = np.fft.rfftfreq(g.size, 1.0 / r.fps)
    return P[(f > lo) & (f < hi)].sum() / P.sum()


# ---------------------------------------------------------------- configuration
def test_config_defaults_and_validation():
    c = SimConfig()
    assert c.epithelium_E_kpa == 0.0 and c.subglottal_modes == () and c.epithelium_profile == ()
    assert not c.has_extensions
    n_edges = len(load_mesh("medium").surface) - 1
    with pytest.raises(ValueError, match=f"expected length {n_edges}"):
        SimConfig(epithelium_E_kpa=30.0, epithelium_profile=(1.0, 2.0))
    for bad in (
        dict(epithelium_E_kpa=-1.0),
        dict(epithelium_E_kpa=float("nan")),
        dict(epithelium_h_mm=0.0),
        dict(epithelium_h_mm=1.0),
        dict(epithelium_profile=(-1.0,) * n_edges),
        dict(epithelium_profile=(float("inf"),) * n_edges),
        dict(subglottal_modes=((0.0, 0.1, 1e6),)),
        dict(subglottal_modes=((600.0, 0.0, 1e6),)),
        dict(subglottal_modes=((600.0, 1.5, 1e6),)),
        dict(subglottal_modes=((600.0, 0.1, -1.0),)),
        dict(subglottal_modes=((600.0, 0.1),)),
        dict(subglottal_modes=((20000.0, 0.1, 1e6),)),
    ):
        with pytest.raises(ValueError):
            SimConfig(**bad)
    # lists (e.g. from JSON) are normalised to hashable tuples; as_dict / replace round-trip
    c = SimConfig(subglottal_modes=[[600, 0.1, 2e6]], epithelium_profile=[1.0] * n_edges, epithelium_E_kpa=30)
    assert c.subglottal_modes == ((600.0, 0.1, 2e6),) and isinstance(c.epithelium_profile, tuple)
    assert c.has_epithelium and c.has_subglottal and hash(c) == hash(SimConfig(**c.as_dict()))
    assert c.replace(dt=2.5e-5).subglottal_modes == c.subglottal_modes


# ---------------------------------------------------------------- epithelium
def test_epithelium_off_is_bit_identical():
    n_edges = len(load_mesh("medium").surface) - 1
    _same(_sim(**SHORT), _sim(**SHORT, epithelium_E_kpa=0.0, epithelium_h_mm=0.08, epithelium_profile=(2.0,) * n_edges))


def test_membrane_matrix_on_pattern():
    """The membrane values on the solver's CSR pattern hold the whole assembled membrane matrix."""
    s = get_system("medium", 0.4995)
    mesh = s.mesh
    Kfull = sum(membrane_unit(mesh))
    rng = np.random.default_rng(0)
    u_full = rng.standard_normal(2 * mesh.n_nodes)
    u_full[np.repeat(mesh.fixed, 2)] = 0.0
    u = u_full[s.dofs]
    Kp = s.matrix(s.ep_vals.sum(axis=0))
    assert abs(Kp - Kp.T).max() < 1e-6 * abs(Kp).max()
    e_full = u_full @ (Kfull @ u_full)
    assert abs(u @ (Kp @ u) - e_full) < 1e-12 * abs(e_full)


def test_membrane_uniform_stretch_gives_E_h_strain():
    """Uniform in-plane stretch eps of the straight superior surface: axial force E' h eps."""
    s = get_system("medium", 0.4995)
    E_kpa, h_mm, eps = 30.0, 0.05, 1e-3
    Ep = E_kpa * 1e3 / (1.0 - s.nu**2)
    z_top = s.sZ.max()
    on_top = np.abs(s.sZ - z_top) < 1e-9
    edges = on_top[:-1] & on_top[1:]  # edges of the flat superior surface
    assert edges.sum() >= 4
    K_ep, D_ep = s.epithelium_values(E_kpa, h_mm, tuple(edges.astype(float)), eta=0.3)
    # every element: the linear field u = eps (X - X_a) stretches it by eps
    for ke in membrane_unit(s.mesh)[:5]:
        idx = np.unique(ke.nonzero()[0])
        X = s.mesh.points[idx // 2, idx % 2]
        uloc = eps * (X - X[0])
        f = Ep * h_mm * 1e-3 * (ke[idx][:, idx] @ uloc)
        assert np.isclose(np.hypot(f[2], f[3]), Ep * h_mm * 1e-3 * eps, rtol=1e-12)
    # the assembled, restricted, reordered matrix: u_x = eps x on the segment (its lateral end x = 0 is fixed)
    u = np.zeros(s.n)
    top = np.nonzero(on_top)[0]
    for j in top:
        if s.sdx[j] >= 0:
            u[s.sdx[j]] = eps * s.sX[j]
    f = s.matrix(K_ep) @ u
    j_med = top[np.argmax(s.sX[top])]  # the medial end of the segment: free
    N = Ep * h_mm * 1e-3 * eps
    assert np.isclose(f[s.sdx[j_med]], N, rtol=1e-10)
    assert abs(f[s.sdz[j_med]]) < 1e-10 * N
    interior = [j for j in top if j != j_med and s.sdx[j] >= 0]
    assert interior and np.max(np.abs(f[[s.sdx[j] for j in interior] + [s.sdz[j] for j in interior]])) < 1e-9 * N
    # Kelvin-Voigt damping: (2 / (1 - nu)) eta h on the same membrane
    assert np.allclose(D_ep, K_ep * (2.0 / (1.0 - s.nu) * 0.3) / Ep, rtol=1e-12, atol=0)


def test_epithelium_raises_lowest_eigenfrequency_monotonically():
    s = get_system("medium", 0.4995)
    si = TABLE3.si()
    K0 = s.stiffness_values((si["E_body"], si["E_lig"], si["E_cover"]))
    M = s.matrix(si["rho"] * s.m_vals).toarray()
    f1 = []
    for E in (0.0, 10.0, 30.0, 100.0):
        K = s.matrix(K0 + s.epithelium_values(E, 0.05)[0]).toarray()
        lam = sla.eigh(K, M, eigvals_only=True, subset_by_index=[0, 2])
        f1.append(np.sqrt(lam[0]) / (2 * np.pi))
    assert abs(f1[0] - 54.9) < 0.5  # :ref:`model`: 54.9 Hz at Table 3
    assert np.all(np.diff(f1) > 0.1), f1


def test_epithelium_profile_scales_stiffness():
    s = get_system("medium", 0.4995)
    n_edges = s.ep_vals.shape[0]
    K1 = s.epithelium_values(30.0, 0.05)[0]
    K2 = s.epithelium_values(30.0, 0.05, (2.0,) * n_edges)[0]
    assert np.allclose(K2, 2.0 * K1)
    with pytest.raises(ValueError, match=f"expected length {n_edges}"):
        s.epithelium_values(30.0, 0.05, (1.0,) * (n_edges + 1))


def test_table3_with_epithelium_runs():
    r0, r = _sim(), _sim(epithelium_E_kpa=30.0, epithelium_h_mm=0.05)
    assert r.ok, r.message
    assert r.f0 > r0.f0 + 1.0  # the stiffer surface raises f0 (64.1 -> 68.8 Hz)
    assert np.ptp(r.gaw) > 5.0  # still oscillates with closure


# ---------------------------------------------------------------- subglottal coupling
def test_subglottal_off_is_bit_identical():
    r0, r1 = _sim(**SHORT), simulate(TABLE3, SimConfig(**SHORT, subglottal_modes=()))
    _same(r0, r1)
    assert r1.p_in.size == 0


@pytest.mark.parametrize(
    "mode,fd",
    [
        ((600.0, 0.1, 2e6), 64.0),
        ((600.0, 0.1, 2e6), 600.0),
        ((600.0, 0.1, 2e6), 450.0),
        ((600.0, 0.02, 1e6), 590.0),
        ((300.0, 0.5, 5e6), 900.0),
    ],
)
def test_resonator_steady_state_response(mode, fd):
    """Prescribed Q = Q0 sin(w t): steady-state p matches |H(jw)|, arg H(jw) of the resonance to < 1 %."""
    h = 5e-5
    f, zeta, Z = mode
    t = h * np.arange(1, int(round(0.5 / h)) + 1)
    q0 = 1e-3
    p = kern.subglottal_response(q0 * np.sin(2 * np.pi * fd * t), kern.subglottal_coefficients([mode], h))
    sel = t > 0.4
    A = np.c_[np.sin(2 * np.pi * fd * t[sel]), np.cos(2 * np.pi * fd * t[sel])]
    a, b = np.linalg.lstsq(A, p[sel], rcond=None)[0]
    resp = (a + 1j * b) / q0  # p = Im(resp q0 e^{jwt})
    w, w0 = 2 * np.pi * fd, 2 * np.pi * f
    H = 2 * zeta * w0 * Z * 1j * w / (w0 * w0 - w * w + 2j * zeta * w0 * w)
    assert abs(abs(resp) / abs(H) - 1) < 0.01
    assert abs(np.angle(resp / H)) < 0.01
    if fd == f:
        assert abs(abs(resp) - Z) < 1e-9 * Z  # prewarped: exact peak at the resonance


def test_small_impedance_converges_linearly_to_uncoupled():
    r0 = _sim(**SHORT)
    d = []
    for Z in (50.0, 100.0, 200.0):
        r = simulate(TABLE3, SimConfig(**SHORT, subglottal_modes=((600.0, 0.1, Z),)))
        assert r.ok
        assert np.allclose(r.p_in, TABLE3.p_sub, atol=Z * 1e-3 * 10)  # |p| <~ Z Q, Q < 1e-3 m^3/s
        d.append(np.max(np.abs(r.gaw - r0.gaw)))
    assert 0 < d[0] < 1e-3 * np.ptp(r0.gaw)
    assert d[1] / d[0] == pytest.approx(2.0, rel=0.02) and d[2] / d[1] == pytest.approx(2.0, rel=0.02)


def test_subglottal_flow_and_p_in_reported():
    r = _sim(subglottal_modes=((600.0, 0.1, 1e6),))
    assert r.ok and r.p_in.shape == r.gaw.shape
    assert np.ptp(r.p_in) > 50.0  # the resonator pressure swings by ~100 Pa
    # flow uses p_in: Q = 1.3 * A_min * sqrt(2 (p_in - p_sup) / rho), up to the one-step coupling lag
    open_ = r.flow > 0.2 * r.flow.max()
    a_sep = 1e-6 * r.config.length_mm * r.config.sep_ratio * r.width[open_]  # m^2
    err_in = np.max(np.abs(r.flow[open_] / (a_sep * np.sqrt(2 * r.p_in[open_] / 1.14)) - 1))
    err_sub = np.max(np.abs(r.flow[open_] / (a_sep * np.sqrt(2 * TABLE3.p_sub / 1.14)) - 1))
    assert err_in < 0.01 and err_sub > 3 * err_in, (err_in, err_sub)


def test_subglottal_coupling_shows_in_the_gaw():
    """600 Hz / zeta 0.1: at Z = 1e6 the GAW carries more energy near the resonance; at Z = 2e6 (equivalent
    low-frequency inertance 2 zeta Z / w = 106 kg/m^4) the Table 3 oscillation is suppressed."""
    r0 = _sim()
    r1 = _sim(subglottal_modes=((600.0, 0.1, 1e6),))
    assert r1.ok and np.ptp(r1.gaw) > 15.0
    assert _band_fraction(r1, 500, 700) > 2.0 * _band_fraction(r0, 500, 700)
    r2 = _sim(subglottal_modes=(MODE,))
    assert r2.ok, r2.message
    assert np.ptp(r0.gaw) > 20.0 and np.ptp(r2.gaw) < 1.0
