"""SimConfig(element=...): the paper's P1 triangle and the locking-free "anp" option
(P1 with a nodally averaged volumetric part, Bonet & Burton 1998).

Expected values come from mechanics (patch test, exact uniform-strain energy, rigid modes,
a divergence-free manufactured solution, an independent numpy assembly), never from the
code's own output.
"""

import math
from functools import cache

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from skfem import Basis, ElementTriP1, ElementVector, Functional, LinearForm, MeshTri, asm

from vfcore import TABLE3, SimConfig, simulate
from vfcore import forward as fw
from vfcore.fem.assemble import ELEMENTS, _shear, _volumetric, assemble_unit, lame, nodal_volumetric
from vfcore.measures import cycle_boundaries, estimate_f0
from vfcore.mesh import load_mesh
from vfcore.solver import _args as args
from vfcore.solver import _kernels as kern
from vfcore.solver.system import get_system

E_TABLE3 = np.array([12150.0, 1808.0, 636.2])  # body, ligament, cover (Pa)


def _boundary_nodes(tri: np.ndarray) -> np.ndarray:
    e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    uniq, cnt = np.unique(e, axis=0, return_counts=True)
    return np.unique(uniq[cnt == 1])


def _geometry(mesh):
    """Areas (nt,) and the element divergence rows B (nt, 6) on interleaved local dofs, by hand."""
    p = mesh.points[mesh.triangles]  # (nt, 3, 2)
    x, z = p[:, :, 0], p[:, :, 1]
    det = (x[:, 1] - x[:, 0]) * (z[:, 2] - z[:, 0]) - (x[:, 2] - x[:, 0]) * (z[:, 1] - z[:, 0])
    area = 0.5 * np.abs(det)
    # gradients of the barycentric coordinates: dL_i/dx = (z_j - z_k)/det, dL_i/dz = (x_k - x_j)/det
    j, k = [1, 2, 0], [2, 0, 1]
    gx = (z[:, j] - z[:, k]) / det[:, None]
    gz = (x[:, k] - x[:, j]) / det[:, None]
    B = np.empty((len(area), 6))
    B[:, 0::2], B[:, 1::2] = gx, gz  # div u = sum_i gx_i ux_i + gz_i uz_i
    return area, B


# ---------------------------------------------------------------- configuration / default path
def test_element_option_validated_and_default_is_p1():
    assert SimConfig().element == "p1"
    assert ELEMENTS == ("p1", "anp")
    SimConfig(element="anp")
    with pytest.raises(ValueError, match="element"):
        SimConfig(element="p2")
    with pytest.raises(ValueError, match="element"):
        assemble_unit(load_mesh("coarse"), 0.4995, element="q1")


def test_p1_path_unchanged():
    """element='p1' is the default code path: identical matrices and an identical simulation."""
    mesh = load_mesh("coarse")
    a, b = assemble_unit(mesh, 0.4995), assemble_unit(mesh, 0.4995, element="p1")
    for A, B in zip((*a.K_layers, a.D1, a.M1), (*b.K_layers, b.D1, b.M1)):
        assert (A != B).nnz == 0
    cfg = SimConfig(mesh="coarse", duration=0.03, discard=0.0)
    r1, r2 = simulate(TABLE3, cfg), simulate(TABLE3, cfg.replace(element="p1"))
    assert np.array_equal(r1.gaw, r2.gaw) and np.array_equal(r1.gaw_hr, r2.gaw_hr)


def test_anp_changes_only_the_volumetric_part():
    """D1 (Kelvin-Voigt, the mu-part) and M1 are the P1 ones; K differs only by lambda (Kbar - Kvol)."""
    mesh = load_mesh("medium")
    nu = 0.4995
    p, q = assemble_unit(mesh, nu), assemble_unit(mesh, nu, element="anp")
    assert (p.D1 != q.D1).nnz == 0 and (p.M1 != q.M1).nnz == 0
    lam1, _ = lame(1.0, nu)
    area, B = _geometry(mesh)
    n = 2 * mesh.n_nodes
    dof = np.empty((len(area), 6), dtype=np.int64)
    dof[:, 0::2], dof[:, 1::2] = 2 * mesh.triangles, 2 * mesh.triangles + 1
    E = E_TABLE3[mesh.layer]
    # element-wise volumetric: sum_e E_e A_e B_e^T B_e
    rows = np.repeat(dof, 6, axis=1).ravel()
    cols = np.tile(dof, (1, 6)).ravel()
    Kvol = sp.csr_matrix(
        sp.coo_matrix((((E * area)[:, None, None] * B[:, :, None] * B[:, None, :]).ravel(), (rows, cols)), shape=(n, n))
    )
    # nodal: C_aj = sum_{e ni a} A_e/3 B_e,j ; V_a = sum A_e/3 ; W_a = sum E_e A_e/3
    na = mesh.n_nodes
    C = sp.csr_matrix(
        sp.coo_matrix(
            (
                np.repeat((area / 3)[:, None, None] * B[:, None, :], 3, axis=1).ravel(),
                (np.repeat(mesh.triangles, 6, axis=1).ravel(), np.tile(dof, (1, 3)).ravel()),
            ),
            shape=(na, n),
        )
    )
    V = np.bincount(mesh.triangles.ravel(), np.repeat(area / 3, 3), minlength=na)
    W = np.bincount(mesh.triangles.ravel(), np.repeat(E * area / 3, 3), minlength=na)
    Kbar = C.T @ sp.diags(W / V**2) @ C
    Kp = sum(e * K for e, K in zip(E_TABLE3, p.K_layers))
    Kq = sum(e * K for e, K in zip(E_TABLE3, q.K_layers))
    ref = lam1 * (Kbar - Kvol)
    assert abs((Kq - Kp) - ref).max() <= 1e-10 * abs(ref).max()


# ---------------------------------------------------------------- exact properties of the anp form
@pytest.mark.parametrize("nu", [0.3, 0.4995])
@pytest.mark.parametrize("mesh_name", ["coarse", "fine"])
def test_anp_patch_test(mesh_name, nu):
    """Homogeneous material: an affine field on the boundary is reproduced inside to 1e-10."""
    mesh = load_mesh(mesh_name)
    K = sum(assemble_unit(mesh, nu, element="anp").K_layers)
    bnd = _boundary_nodes(mesh.triangles)
    inner = np.setdiff1d(np.arange(mesh.n_nodes), bnd)
    dof_b = np.sort(np.concatenate([2 * bnd, 2 * bnd + 1]))
    dof_i = np.sort(np.concatenate([2 * inner, 2 * inner + 1]))
    for A, b in (
        (np.array([[0.3, -0.7], [1.1, 0.4]]), np.array([1e-3, -2e-3])),
        (np.array([[-1.0, 0.25], [0.5, 2.0]]), np.array([0.0, 5e-4])),
    ):
        exact = (mesh.points @ A.T + b).ravel()
        ui = spla.spsolve(sp.csc_matrix(K[dof_i][:, dof_i]), -K[dof_i][:, dof_b] @ exact[dof_b])
        assert np.max(np.abs(ui - exact[dof_i])) <= 1e-10 * np.max(np.abs(exact[dof_i]))


@pytest.mark.parametrize("element", ELEMENTS)
def test_uniform_strain_energy_is_exact(element):
    """Layered material, affine u with strain eps: u'Ku = sum_e A_e E_e (lam tr(eps)^2 + 2 mu eps:eps)."""
    mesh = load_mesh("medium")
    nu = 0.4995
    U = assemble_unit(mesh, nu, element=element)
    K = sum(e * Kl for e, Kl in zip(E_TABLE3, U.K_layers))
    lam1, mu1 = lame(1.0, nu)
    area, _ = _geometry(mesh)
    A = np.array([[0.3, -0.7], [1.1, 0.4]])
    eps = 0.5 * (A + A.T)
    u = (mesh.points @ A.T).ravel()
    exact = np.sum(area * E_TABLE3[mesh.layer]) * (lam1 * np.trace(eps) ** 2 + 2 * mu1 * np.sum(eps * eps))
    assert u @ (K @ u) == pytest.approx(exact, rel=1e-10)


def test_anp_symmetric_semidefinite_rigid_modes_only():
    mesh = load_mesh("medium")
    U = assemble_unit(mesh, 0.4995, element="anp")
    K = sum(e * Kl for e, Kl in zip(E_TABLE3, U.K_layers))
    assert abs(K - K.T).max() <= 1e-12 * abs(K).max()
    w = np.linalg.eigvalsh(K.toarray())
    assert w.min() >= -1e-10 * w.max()
    assert np.sum(w < 1e-10 * w.max()) == 3  # no spurious zero-energy mode
    x, z = mesh.points[:, 0], mesh.points[:, 1]
    for r in (
        np.column_stack([np.ones_like(x), 0 * x]),
        np.column_stack([0 * x, np.ones_like(x)]),
        np.column_stack([-z, x]),
    ):
        r = r.ravel()
        assert np.max(np.abs(K @ r)) <= 1e-10 * abs(K).max() * np.max(np.abs(r))
    # with the fixed boundary the free-dof system is positive definite (Cholesky succeeds)
    s = get_system("medium", 0.4995, "anp")
    s.factor(s.stiffness_values(E_TABLE3))
    assert s.indices.size > get_system("medium", 0.4995).indices.size  # wider stencil (two-ring coupling)


# ---------------------------------------------------------------- locking: manufactured solution
_PI = math.pi


def _S(t, d=0):
    """sin^2(pi t) and its derivatives."""
    return [
        np.sin(_PI * t) ** 2,
        _PI * np.sin(2 * _PI * t),
        2 * _PI**2 * np.cos(2 * _PI * t),
        -4 * _PI**3 * np.sin(2 * _PI * t),
    ][d]


@cache
def _locking_error(level: int, nu: float, element: str) -> float:
    """Relative L2 error on the unit square (one-diagonal mesh), u = curl psi, psi = S(x) S(y).

    u = (S(x) S'(y), -S'(x) S(y)) is divergence free and zero on the boundary, so
    f = -mu lap u for every lambda: the exact solution does not depend on nu.
    """
    lam, mu = lame(1.0, nu)
    m = MeshTri().refined(level)
    b = Basis(m, ElementVector(ElementTriP1()), intorder=4)
    Kv = asm(_volumetric, b) if element == "p1" else nodal_volumetric(m)[0]
    K = sp.csr_matrix(lam * Kv + mu * asm(_shear, b))

    @LinearForm
    def load(v, w):
        x, y = w.x
        f1 = -mu * (_S(x, 2) * _S(y, 1) + _S(x) * _S(y, 3))
        f2 = mu * (_S(x, 3) * _S(y) + _S(x, 1) * _S(y, 2))
        return f1 * v.value[0] + f2 * v.value[1]

    f = asm(load, b)
    inner = b.complement_dofs(b.get_dofs().all())
    uh = np.zeros(b.N)
    uh[inner] = spla.spsolve(sp.csc_matrix(K[inner][:, inner]), f[inner])

    @Functional
    def err2(w):
        x, y = w.x
        return (w["uh"].value[0] - _S(x) * _S(y, 1)) ** 2 + (w["uh"].value[1] + _S(x, 1) * _S(y)) ** 2

    @Functional
    def norm2(w):
        x, y = w.x
        return (_S(x) * _S(y, 1)) ** 2 + (_S(x, 1) * _S(y)) ** 2

    return math.sqrt(asm(err2, b, uh=b.interpolate(uh)) / asm(norm2, b))


def test_anp_converges_where_p1_locks():
    levels = (2, 3, 4, 5)  # h = 1/8 .. 1/64
    e_p1 = np.array([_locking_error(k, 0.4995, "p1") for k in levels])
    e_anp = np.array([_locking_error(k, 0.4995, "anp") for k in levels])
    e_anp_c = np.array([_locking_error(k, 0.3, "anp") for k in levels])
    o_p1, o_anp = np.log2(e_p1[:-1] / e_p1[1:]), np.log2(e_anp[:-1] / e_anp[1:])
    print("P1 ", e_p1, o_p1, "\nANP", e_anp, o_anp, "\nANP nu=0.3", e_anp_c)
    # P1 locks: the error stays O(1) (the discrete solution is almost zero) and shrinks far slower than h^2
    assert e_p1[-1] > 0.5 and np.all(o_p1 < 0.6)
    # ANP: second order, uniform in nu (as accurate as at nu = 0.3), > 20x better than P1 at h = 1/64
    assert np.all(o_anp[1:] > 1.8)
    assert e_anp[-1] < e_p1[-1] / 20
    assert e_anp[-1] < 1.5 * e_anp_c[-1]


# ---------------------------------------------------------------- time integration with anp
def test_anp_newmark_conserves_energy_undamped():
    s = get_system("medium", 0.4995, "anp")
    si = TABLE3.si()
    K_vals = s.stiffness_values((si["E_body"], si["E_lig"], si["E_cover"]))
    m_vals, d_vals = si["rho"] * s.m_vals, 1e-12 * s.d_vals
    K, M = s.matrix(K_vals), s.matrix(m_vals)
    f = np.zeros(s.n)
    w = s.mesh.surface_weights()
    f[s.sdx[s.sdx >= 0]] = -500.0 * w[s.sdx >= 0]
    u = f.copy()
    s.solve(s.factor(K_vals), u)
    a = -(K @ u)
    s.solve(s.factor(m_vals), a)
    v = np.zeros(s.n)
    h, n_steps = 5e-5, 800
    cM, cD, cK = kern.effective_scales(h, 1.0)
    Lx = s.factor(cK * K_vals + cD * d_vals + cM * m_vals)
    am, af, beta, gamma = kern.newmark_coefficients(h, 1.0)
    tu, tv = np.zeros((n_steps, s.n)), np.zeros((n_steps, s.n))
    u0 = u.copy()
    st = kern.integrate(
        args.Stepper(n_steps, h, am, af, beta, gamma),
        args.Pattern(s.indptr, s.indices, s.Lp, s.Lj, s.sdx, s.sdz, s.sX, s.sZ),
        args.Model(0.0, 0.0, 1.3, 1.0, fw.CLOSED_TOL, 0.0, 0, fw.BLOWUP),
        args.Matrices(K_vals, m_vals, d_vals, Lx, s.contact_columns(Lx)),
        args.State(u, v, a),
        args.Outputs(
            np.zeros(n_steps),
            np.zeros(n_steps),
            np.zeros((n_steps, s.sdx.size)),
            np.zeros((0, s.sdx.size)),
            np.zeros(0),
            1,
            tu,
            tv,
            np.zeros(1, dtype=np.int64),
        ),
    )
    assert st == 0 and np.abs(tu).max() > 1e-5
    e0 = 0.5 * u0 @ (K @ u0)
    energy = 0.5 * np.einsum("ij,ij->i", tv, (M @ tv.T).T) + 0.5 * np.einsum("ij,ij->i", tu, (K @ tu.T).T)
    assert np.abs(energy - e0).max() < 1e-8 * e0


# ---------------------------------------------------------------- Table 3: every shipped mesh oscillates
@cache
def _table3(mesh: str, element: str):
    return simulate(TABLE3, SimConfig(mesh=mesh, element=element))


def _limit_cycle(r):
    g = r.gaw
    last = g[-int(round(0.1 * r.fps)) :]
    f0 = estimate_f0(g, r.fps)
    b = cycle_boundaries(g, r.fps, f0)
    peaks = np.array([g[i : j + 1].max() for i, j in zip(b[:-1], b[1:])])
    return f0, peaks, last


@pytest.mark.parametrize("mesh", ["coarse", "medium", "fine"])
def test_anp_all_meshes_oscillate_at_table3(mesh):
    r = _table3(mesh, "anp")
    assert r.ok, r.message
    f0, peaks, last = _limit_cycle(r)
    print(mesh, "f0", f0, "peak", peaks.mean(), "p2p(last 100 ms)", np.ptp(last))
    assert np.ptp(last) > 0.5 and 45.0 <= f0 <= 65.0
    assert peaks.size >= 12 and 20.0 <= peaks.mean() <= 50.0
    assert last.min() == 0.0  # the glottis closes (collision) every cycle


def test_anp_f0_agrees_across_meshes():
    f0 = [_limit_cycle(_table3(m, "anp"))[0] for m in ("coarse", "medium", "fine")]
    print("f0 coarse/medium/fine", f0)
    assert max(f0) - min(f0) < 0.05 * np.mean(f0)
