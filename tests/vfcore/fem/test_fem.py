"""P1 plane-strain assembly (vfcore.fem.assemble) against exact properties of the FE space.

Expected values are derived from mechanics (patch test, rigid-body modes, total mass,
a manufactured Navier solution), never recorded from the code's output.
"""

import math

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from skfem import Basis, ElementTriP1, ElementVector, Functional, LinearForm, MeshTri, asm

from vfcore.fem.assemble import _shear, _volumetric, assemble_unit, lame
from vfcore.mesh import load_mesh


def _boundary_nodes(tri: np.ndarray) -> np.ndarray:
    e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    uniq, cnt = np.unique(e, axis=0, return_counts=True)
    return np.unique(uniq[cnt == 1])


def _patch_solve(K: sp.spmatrix, pts: np.ndarray, nodes: np.ndarray, bnd: np.ndarray, A, b):
    """Impose u = A x + b on ``bnd`` (interleaved dofs), solve K u = 0 on the rest of ``nodes``."""
    n_full = 2 * len(pts)
    exact = (pts @ np.asarray(A).T + b).ravel()  # interleaved: (x0, z0, x1, z1, ...)
    dof_b = np.sort(np.concatenate([2 * bnd, 2 * bnd + 1]))
    inner = np.setdiff1d(nodes, bnd)
    dof_i = np.sort(np.concatenate([2 * inner, 2 * inner + 1]))
    K = sp.csr_matrix(K)
    u = np.zeros(n_full)
    u[dof_b] = exact[dof_b]
    rhs = -K[dof_i][:, dof_b] @ u[dof_b]
    u[dof_i] = spla.spsolve(sp.csc_matrix(K[dof_i][:, dof_i]), rhs)
    return u[dof_i], exact[dof_i]


# Affine fields with O(1) strain; points are in metres (~1e-2), so scale b accordingly.
AFFINE = [
    (np.array([[0.3, -0.7], [1.1, 0.4]]), np.array([1e-3, -2e-3])),
    (np.array([[-1.0, 0.25], [0.5, 2.0]]), np.array([0.0, 5e-4])),
]


@pytest.mark.parametrize("nu", [0.0, 0.3, 0.45, 0.4995])
@pytest.mark.parametrize("mesh_name", ["coarse", "medium"])
def test_patch_test_homogeneous(mesh_name, nu):
    """Homogeneous material: an affine field imposed on the whole boundary is reproduced exactly inside."""
    mesh = load_mesh(mesh_name)
    U = assemble_unit(mesh, nu)
    K = sum(U.K_layers)  # E = 1 everywhere
    bnd = _boundary_nodes(mesh.triangles)
    nodes = np.arange(mesh.n_nodes)
    assert np.setdiff1d(nodes, bnd).size > 10  # there are interior nodes to check
    for A, b in AFFINE:
        ui, ex = _patch_solve(K, mesh.points, nodes, bnd, A, b)
        assert np.max(np.abs(ui - ex)) <= 1e-10 * np.max(np.abs(ex))


@pytest.mark.parametrize("nu", [0.3, 0.4995])
def test_patch_test_each_layer(nu):
    """Each layer matrix passes the patch test on its own subdomain, and the layered
    stiffness sum E_l K_l is the assembly of the piecewise-constant E (linearity).

    (A single affine field is NOT an equilibrium state of a body with different E per
    layer -- the traction jumps across curved interfaces -- so the multi-material check
    is done per layer plus linearity, not with one global affine field.)
    """
    mesh = load_mesh("medium")
    U = assemble_unit(mesh, nu)
    for k in range(3):
        tri = mesh.triangles[mesh.layer == k]
        assert len(tri) > 0
        nodes = np.unique(tri)
        bnd = _boundary_nodes(tri)
        inner = np.setdiff1d(nodes, bnd)
        if inner.size == 0:  # thin layer without interior nodes: nothing to check
            continue
        for A, b in AFFINE:
            ui, ex = _patch_solve(U.K_layers[k], mesh.points, nodes, bnd, A, b)
            assert np.max(np.abs(ui - ex)) <= 1e-10 * np.max(np.abs(ex))
    # linearity: sum_l E_l K_l equals the direct skfem assembly with elementwise E
    E = np.array([12150.0, 1808.0, 636.2])
    Ksum = sum(e * Kl for e, Kl in zip(E, U.K_layers))
    m = MeshTri(mesh.points.T.copy(), mesh.triangles.T.copy())
    basis = Basis(m, ElementVector(ElementTriP1()))
    lam1, mu1 = lame(1.0, nu)
    Ee = E[mesh.layer]
    from skfem import BilinearForm
    from skfem.helpers import ddot, div, sym_grad

    @BilinearForm
    def elastic(u, v, w):
        return w["E"] * (lam1 * div(u) * div(v) + mu1 * 2.0 * ddot(sym_grad(u), sym_grad(v)))

    Kd = asm(elastic, basis, E=Ee[:, None] * np.ones((1, basis.X.shape[1])))
    perm = np.empty(2 * mesh.n_nodes, dtype=np.int64)
    perm[0::2], perm[1::2] = basis.nodal_dofs[0], basis.nodal_dofs[1]
    Kd = sp.csr_matrix(Kd)[perm][:, perm]
    assert abs(Ksum - Kd).max() <= 1e-10 * abs(Kd).max()


@pytest.mark.parametrize("nu", [0.3, 0.4995])
def test_rigid_body_modes_null_space(nu):
    mesh = load_mesh("medium")
    U = assemble_unit(mesh, nu)
    E = (12150.0, 1808.0, 636.2)
    K = sum(e * Kl for e, Kl in zip(E, U.K_layers))
    x, z = mesh.points[:, 0], mesh.points[:, 1]
    modes = [
        np.column_stack([np.ones_like(x), 0 * x]),
        np.column_stack([0 * x, np.ones_like(x)]),
        np.column_stack([-z, x]),
    ]
    scale = abs(K).max()
    for r in modes:
        r = r.ravel()
        assert np.max(np.abs(K @ r)) <= 1e-10 * scale * np.max(np.abs(r))
        assert np.max(np.abs(U.D1 @ r)) <= 1e-10 * abs(U.D1).max() * np.max(np.abs(r))
    # and the null space is exactly three-dimensional: a non-rigid mode has positive energy
    strain = np.column_stack([x, 0 * x]).ravel()  # uniform stretch
    assert strain @ (K @ strain) > 1e-6 * scale * (strain @ strain)


def test_mass_total_and_symmetry():
    for name in ("coarse", "medium", "fine"):
        mesh = load_mesh(name)
        U = assemble_unit(mesh, 0.4995)
        p = mesh.points[mesh.triangles]
        area = (
            0.5
            * np.abs(
                (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0])
            ).sum()
        )
        rho = 1051.0
        assert rho * U.M1.sum() == pytest.approx(rho * area * 2, rel=1e-12)
        # x- and z-blocks each carry the full mass, and do not couple
        ex = np.zeros(2 * mesh.n_nodes)
        ex[0::2] = 1.0
        ez = 1.0 - ex
        assert ex @ U.M1 @ ex == pytest.approx(area, rel=1e-12)
        assert abs(ex @ U.M1 @ ez) <= 1e-14 * area
        for A in (*U.K_layers, U.D1, U.M1):
            assert abs(A - A.T).max() <= 1e-12 * abs(A).max()
        # D1 (the shear part) is positive semidefinite with the 3 rigid modes as null space
        w = np.linalg.eigvalsh(U.D1.toarray())
        assert w.min() >= -1e-10 * w.max()
        assert np.sum(w < 1e-10 * w.max()) == 3
        # M1 positive definite
        assert np.linalg.eigvalsh(U.M1.toarray()).min() > 0


def test_invalid_nu_rejected():
    mesh = load_mesh("coarse")
    for nu in (0.5, 0.6, -1.0):
        with pytest.raises(ValueError, match="nu"):
            assemble_unit(mesh, nu)


def _manufactured_error(level: int, nu: float) -> tuple[float, float]:
    """L2 error of the P1 solution of -div sigma(u) = f on the unit square, u = 0 on the boundary.

    u1 = sin(pi x) sin(pi y), u2 = x (1-x) y (1-y); f from Navier's equations
    f = -(lam + mu) grad div u - mu lap u (derived by hand below).
    """
    lam, mu = lame(1.0, nu)
    pi = math.pi
    m = MeshTri.init_symmetric().refined(level)
    basis = Basis(m, ElementVector(ElementTriP1()), intorder=4)
    K = lam * asm(_volumetric, basis) + mu * asm(_shear, basis)

    def derivs(x, y):
        s = np.sin(pi * x) * np.sin(pi * y)
        u1xx = -(pi**2) * s
        u1yy = -(pi**2) * s
        u1xy = pi**2 * np.cos(pi * x) * np.cos(pi * y)
        u2xx = -2 * y * (1 - y)
        u2yy = -2 * x * (1 - x)
        u2xy = (1 - 2 * x) * (1 - 2 * y)
        f1 = -(lam + mu) * (u1xx + u2xy) - mu * (u1xx + u1yy)
        f2 = -(lam + mu) * (u1xy + u2yy) - mu * (u2xx + u2yy)
        return f1, f2

    @LinearForm
    def load(v, w):
        f1, f2 = derivs(w.x[0], w.x[1])
        return f1 * v.value[0] + f2 * v.value[1]

    f = asm(load, basis)
    D = basis.get_dofs().all()
    uh = np.zeros(basis.N)
    free = basis.complement_dofs(D)
    uh[free] = spla.spsolve(sp.csc_matrix(K[free][:, free]), f[free])

    @Functional
    def err2(w):
        x, y = w.x[0], w.x[1]
        e1 = w["uh"].value[0] - np.sin(pi * x) * np.sin(pi * y)
        e2 = w["uh"].value[1] - x * (1 - x) * y * (1 - y)
        return e1**2 + e2**2

    e = math.sqrt(asm(err2, basis, uh=basis.interpolate(uh)))
    h = 1.0 / 2 ** (level + 1)
    return h, e


@pytest.mark.parametrize("nu", [0.3])
def test_manufactured_solution_second_order_L2(nu):
    hs, es = zip(*[_manufactured_error(k, nu) for k in (2, 3, 4, 5)])
    orders = [math.log(es[i] / es[i + 1]) / math.log(hs[i] / hs[i + 1]) for i in range(len(es) - 1)]
    print("L2 errors", es, "orders", orders)
    assert es[-1] < es[0] / 30
    assert orders[-1] == pytest.approx(2.0, abs=0.15)
    assert all(o > 1.7 for o in orders[1:])
