"""P1 plane-strain elasticity, Kelvin-Voigt damping and mass matrices with scikit-fem.

Hadwin et al. (2019), Section 3: linear isotropic plane strain, uniform density,
Kelvin-Voigt viscosity by replacing mu with mu + eta d/dt. Because lambda and mu are
both proportional to E at fixed nu, K = sum_layers E_layer * K_layer(E = 1), and the
damping matrix is D = eta * D1 where D1 is the shear (mu-) part with mu = 1. The mass
matrix is M = rho * M1. All matrices are per unit depth (N/m, SI).

Elements (``ELEMENTS``):

* ``"p1"`` (default, the paper's): linear triangles, lambda-part int lam div u div v.
* ``"anp"``: the same P1 displacement space with the lambda- (volumetric) part built from
  nodally averaged dilatations -- the average-nodal-pressure idea of Bonet & Burton (1998),
  Commun. Numer. Meth. Engng 14:437-449, applied to the 2D plane-strain triangle. With
  phi_a the P1 hat function of node a,

      V_a = int phi_a dx,   d_a . u = (1/V_a) int phi_a div u dx   (nodal dilatation),
      K_vol = sum_a lam_a V_a d_a d_a^T,  lam_a V_a = int phi_a lam dx,

  i.e. K_vol = C^T diag(V^lam / V^2) C with C_aj = int phi_a div(psi_j) dx. The shear part
  2 mu eps(u):eps(v) stays element-wise (it keeps the element free of zero-energy modes, and the
  Kelvin-Voigt damping D = eta * D1, the mu-part, is unchanged). Only lambda -> infinity
  causes locking, so only the lambda-part is averaged: n_nodes constraints on 2 dofs per node
  instead of one per triangle (~2 per node), which removes the over-constraint.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from skfem import Basis, BilinearForm, ElementTriP1, ElementVector, LinearForm, MeshTri, asm
from skfem.helpers import ddot, div, dot, sym_grad

from ..mesh import FoldMesh

#: Displacement elements: "p1" = the paper's linear triangle, "anp" = P1 with a nodally
#: averaged volumetric (lambda) part (Bonet & Burton 1998), locking-free as nu -> 1/2.
ELEMENTS = ("p1", "anp")


@BilinearForm
def _volumetric(u, v, w):
    return div(u) * div(v)


@BilinearForm
def _shear(u, v, w):
    # mu-part of the plane-strain stiffness with mu = 1: 2 eps(u):eps(v)
    return 2.0 * ddot(sym_grad(u), sym_grad(v))


@BilinearForm
def _mass(u, v, w):
    return dot(u, v)


@BilinearForm
def _nodal_div(u, q, w):
    # trial: vector P1 displacement, test: scalar P1 hat function -> C_aj = int phi_a div psi_j
    return div(u) * q


@LinearForm
def _nodal_volume(q, w):
    return q


def lame(E: float, nu: float) -> tuple[float, float]:
    """Lame parameters (lambda, mu) of Young's modulus E and Poisson ratio nu."""
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


@dataclass(frozen=True)
class UnitMatrices:
    """Layer stiffnesses at E = 1, shear damping at eta = 1, mass at rho = 1 (full dofs).

    Dofs are node-interleaved: dof 2*i is x of node i, 2*i + 1 is z.
    """

    K_layers: tuple[sp.csr_matrix, ...]  # one per layer (body, ligament, cover)
    D1: sp.csr_matrix
    M1: sp.csr_matrix
    nu: float
    element: str = "p1"


def skfem_mesh(mesh: FoldMesh) -> MeshTri:
    return MeshTri(mesh.points.T.copy(), mesh.triangles.T.copy())


def _interleave_perm(basis: Basis) -> np.ndarray:
    """perm such that A_interleaved = A[perm][:, perm] (dof 2i -> x of node i)."""
    nd = basis.nodal_dofs  # (2, n_nodes)
    perm = np.empty(2 * nd.shape[1], dtype=np.int64)
    perm[0::2] = nd[0]
    perm[1::2] = nd[1]
    return perm


def nodal_volumetric(m: MeshTri, elements: np.ndarray | None = None) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Nodally averaged volumetric form of the P1 vector space on ``m`` (skfem dof order).

    Returns (Kbar, C): Kbar = C^T diag(V_sub / V^2) C, the form sum_a V_sub_a (d_a.u)(d_a.v)
    with the nodal dilatation d_a.u = (C u)_a / V_a averaged over the whole patch of node a
    (all elements), weighted by the part V_sub_a = int_{elements} phi_a of its nodal volume
    that lies in ``elements`` (all if None). Summing Kbar over a partition of the elements
    gives C^T diag(1/V) C. C (n_nodes x n_dofs): C_aj = int phi_a div psi_j.
    """
    vec = Basis(m, ElementVector(ElementTriP1()))
    sca = Basis(m, ElementTriP1())
    C = sp.csr_matrix(asm(_nodal_div, vec, sca))
    V = asm(_nodal_volume, sca)
    Vsub = V if elements is None else asm(_nodal_volume, Basis(m, ElementTriP1(), elements=elements))
    return sp.csr_matrix(C.T @ sp.diags(Vsub / V**2) @ C), C


def assemble_unit(mesh: FoldMesh, nu: float, n_layers: int = 3, element: str = "p1") -> UnitMatrices:
    """Assemble the unit matrices of ``mesh`` at Poisson ratio ``nu`` with ``element`` (see ELEMENTS)."""
    if not (-1.0 < nu < 0.5):
        raise ValueError(f"Poisson ratio nu must lie in (-1, 0.5), got {nu}")
    if element not in ELEMENTS:
        raise ValueError(f"element must be one of {ELEMENTS}, got {element!r}")
    m = skfem_mesh(mesh)
    e = ElementVector(ElementTriP1())
    full = Basis(m, e)
    perm = _interleave_perm(full)
    lam1, mu1 = lame(1.0, nu)
    K_layers = []
    for k in range(n_layers):
        idx = np.nonzero(mesh.layer == k)[0]
        if idx.size == 0:
            K_layers.append(sp.csr_matrix((2 * mesh.n_nodes, 2 * mesh.n_nodes)))
            continue
        b = Basis(m, e, elements=idx)
        if element == "p1":
            Kk = lam1 * asm(_volumetric, b) + mu1 * asm(_shear, b)
        else:
            Kk = lam1 * nodal_volumetric(m, idx)[0] + mu1 * asm(_shear, b)
        K_layers.append(sp.csr_matrix(Kk)[perm][:, perm])
    D1 = sp.csr_matrix(asm(_shear, full))[perm][:, perm]
    M1 = sp.csr_matrix(asm(_mass, full))[perm][:, perm]
    return UnitMatrices(K_layers=tuple(K_layers), D1=D1, M1=M1, nu=nu, element=element)


def membrane_unit(mesh: FoldMesh) -> tuple[sp.csr_matrix, ...]:
    """Unit stiffness of a membrane (2-node bar) on each free-surface edge (full dofs).

    Edge e joins surface nodes ``mesh.surface[e]`` and ``mesh.surface[e + 1]`` (inferior ->
    superior), reference length l_e and unit tangent t. Its matrix, for axial rigidity
    E' h = 1 N/m (per unit depth), is the linear (small-strain) bar

        k_e = (1 / l_e) [[t t^T, -t t^T], [-t t^T, t t^T]]

    so a uniform in-plane stretch eps of the edge gives the axial force E' h eps. The
    epithelium stiffness is ``E' h * sum_e c_e k_e`` (see :ref:`model-extensions`).
    """
    s = mesh.surface
    out = []
    n_full = 2 * mesh.n_nodes
    for e in range(len(s) - 1):
        a, b = int(s[e]), int(s[e + 1])
        d = mesh.points[b] - mesh.points[a]
        le = float(np.hypot(d[0], d[1]))
        t = d / le
        tt = np.outer(t, t) / le
        ke = np.block([[tt, -tt], [-tt, tt]])
        idx = np.array([2 * a, 2 * a + 1, 2 * b, 2 * b + 1])
        rows = np.repeat(idx, 4)
        cols = np.tile(idx, 4)
        out.append(sp.csr_matrix((ke.ravel(), (rows, cols)), shape=(n_full, n_full)))
    return tuple(out)
