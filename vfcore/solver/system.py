"""The discrete system of one mesh: free dofs, fill-reducing order, matrices, Cholesky pattern.

Built once per (mesh, nu, element) and cached; per parameter vector only the values of the
effective stiffness change (K = sum E_l K_l, D = eta D1, M = rho M1 share one sparsity
pattern), so a simulation costs one sparse Cholesky factorisation (on the symbolic pattern
computed here once) plus the time loop.

Ordering: minimum degree on the dof graph (Tinney & Walker 1967, scheme 2; ties broken by the
lower index, so the order is deterministic). On the shipped meshes it leaves 3,303 nonzeros in
the factor of the medium mesh (2,453 coarse, 4,677 fine) against 6,540 stored and 3,771 filled
entries of the reverse Cuthill-McKee band used before (docs/model.md, "Speed").
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.sparse as sp

from ..fem.assemble import assemble_unit, membrane_unit
from ..mesh import FoldMesh, load_mesh
from . import _kernels as kern


@dataclass(frozen=True)
class System:
    """Free-dof system in minimum-degree order.

    Attributes
    ----------
    mesh : the FoldMesh.
    dofs : (n,) full (node-interleaved) dof index of each solver dof.
    indptr, indices : CSR pattern (n x n) shared by all matrices.
    k_vals : (n_layers, nnz) unit layer stiffness values; d_vals, m_vals : (nnz,).
    Lp, Lj : row-CSR pattern of the lower Cholesky factor L (columns ascending, the diagonal
        last in each row); values come from :meth:`factor`.
    sdx, sdz : (m,) solver dof of x / z of each surface node (-1 if fixed).
    sX, sZ : (m,) reference surface coordinates, m.
    ep_vals : (m - 1, nnz) unit membrane (epithelium) stiffness of each free-surface edge on the
        shared pattern (axial rigidity 1 N/m; :func:`vfcore.fem.assemble.membrane_unit`).
    """

    mesh: FoldMesh
    nu: float
    dofs: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    k_vals: np.ndarray
    d_vals: np.ndarray
    m_vals: np.ndarray
    Lp: np.ndarray
    Lj: np.ndarray
    sdx: np.ndarray
    sdz: np.ndarray
    sX: np.ndarray
    sZ: np.ndarray
    ep_vals: np.ndarray | None = None
    element: str = "p1"

    @property
    def n(self) -> int:
        return self.dofs.size

    def matrix(self, vals: np.ndarray) -> sp.csr_matrix:
        return sp.csr_matrix((vals, self.indices, self.indptr), shape=(self.n, self.n))

    def stiffness_values(self, E_layers) -> np.ndarray:
        return np.tensordot(np.asarray(E_layers, dtype=float), self.k_vals, axes=1)

    def epithelium_values(
        self, E_kpa: float, h_mm: float, profile=(), eta: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """CSR values (on the shared pattern) of the epithelium membrane: (stiffness, damping).

        Stiffness ``E' h sum_e c_e k_e`` with E' = E / (1 - nu^2) (plane strain), h in m and c_e the
        ``profile`` multipliers (() = all 1). Damping: Kelvin-Voigt as in the bulk (mu -> mu + eta d/dt at
        fixed nu, E' = 2 mu / (1 - nu)), i.e. ``(2 / (1 - nu)) eta h sum_e c_e k_e``; eta in Pa s.
        """
        n_edges = self.ep_vals.shape[0]
        c = np.ones(n_edges) if len(profile) == 0 else np.asarray(profile, dtype=float)
        if c.shape != (n_edges,):
            raise ValueError(
                f"epithelium_profile must have one multiplier per free-surface edge of mesh "
                f"{self.mesh.name!r}: expected length {n_edges}, got {c.size}"
            )
        unit = c @ self.ep_vals
        h = h_mm * 1e-3
        return (E_kpa * 1e3 / (1.0 - self.nu**2) * h) * unit, (2.0 / (1.0 - self.nu) * eta * h) * unit

    @property
    def nnz_factor(self) -> int:
        return int(self.Lj.size)

    def factor(self, vals: np.ndarray) -> np.ndarray:
        """Cholesky factor values (on ``Lp, Lj``; diagonal stored as 1 / L_ii) of the symmetric
        matrix with CSR values ``vals``."""
        Lx = np.empty(self.Lj.size)
        info = kern.sparse_cholesky(self.indptr, self.indices, vals, self.Lp, self.Lj, Lx)
        if info != 0:
            raise np.linalg.LinAlgError(f"matrix not positive definite (minor {info})")
        return Lx

    def solve(self, Lx: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Solve A x = b in place (and return b) for A factored by :meth:`factor`."""
        kern.chol_solve(self.Lp, self.Lj, Lx, b)
        return b

    def contact_columns(self, Lx: np.ndarray) -> np.ndarray:
        """(n, m) columns A^{-1} e_{sdx[j]} for the factored A (zero for fixed nodes)."""
        m = self.sdx.size
        G = np.zeros((self.n, m))
        for j in range(m):
            if self.sdx[j] >= 0:
                col = np.zeros(self.n)
                col[self.sdx[j]] = 1.0
                kern.chol_solve(self.Lp, self.Lj, Lx, col)
                G[:, j] = col
        return G


def _on_pattern(A: sp.spmatrix, pattern: sp.csr_matrix) -> np.ndarray:
    A = sp.csr_matrix(A)
    rows = np.repeat(np.arange(pattern.shape[0]), np.diff(pattern.indptr))
    return np.asarray(A[rows, pattern.indices]).ravel()


def minimum_degree(pattern: sp.csr_matrix) -> np.ndarray:
    """Minimum-degree elimination order of the (structurally symmetric) ``pattern``.

    Plain (not approximate) minimum degree on the elimination graph: repeatedly eliminate the
    vertex of least current degree (lowest index on ties) and join its neighbours into a clique.
    The least degree comes from a heap of (degree, vertex) entries, stale ones skipped, so a step
    costs O(d^2 + log n) rather than a scan of every live vertex.
    """
    n = pattern.shape[0]
    adj = [set(pattern.indices[pattern.indptr[i] : pattern.indptr[i + 1]].tolist()) - {i} for i in range(n)]
    alive = np.ones(n, dtype=bool)
    heap = [(len(adj[i]), i) for i in range(n)]
    heapq.heapify(heap)
    order = []
    while heap:
        d, v = heapq.heappop(heap)
        if not alive[v] or d != len(adj[v]):
            continue
        nb = adj[v]
        for w in nb:
            adj[w] |= nb
            adj[w] -= {w, v}
            heapq.heappush(heap, (len(adj[w]), w))
        alive[v] = False
        adj[v] = set()
        order.append(v)
    return np.asarray(order, dtype=np.int64)


def cholesky_pattern(pattern: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray]:
    """Row-CSR pattern (Lp, Lj) of the lower Cholesky factor of a matrix with ``pattern``
    (symbolic elimination; columns ascending in each row, the diagonal last).

    Row i of L holds i and every column reached by climbing the elimination tree from each
    j < i of row i of the matrix until i (Davis 2006, Direct Methods for Sparse Linear Systems,
    sections 4.1-4.2): memory O(nnz(L)), not the O(n^2) of a dense elimination.
    """
    n = pattern.shape[0]
    ptr, idx = pattern.indptr, pattern.indices
    parent = np.full(n, -1, dtype=np.int64)
    ancestor = np.full(n, -1, dtype=np.int64)
    for i in range(n):
        for j in idx[ptr[i] : ptr[i + 1]]:
            # climb from j to its root, pointing the path at i (path compression)
            while j != -1 and j < i:
                nxt = ancestor[j]
                ancestor[j] = i
                if nxt == -1:
                    parent[j] = i
                j = nxt
    mark = np.full(n, -1, dtype=np.int64)
    rows = []
    for i in range(n):
        mark[i] = i
        r = []
        for j in idx[ptr[i] : ptr[i + 1]]:
            while j < i and mark[j] != i:
                r.append(j)
                mark[j] = i
                j = parent[j]
        r.sort()
        r.append(i)
        rows.append(r)
    Lp = np.concatenate([[0], np.cumsum([len(r) for r in rows])]).astype(np.int64)
    Lj = np.fromiter((j for r in rows for j in r), dtype=np.int64, count=int(Lp[-1]))
    return Lp, Lj


def build_system(mesh: FoldMesh, nu: float, element: str = "p1") -> System:
    U = assemble_unit(mesh, nu, element=element)
    free_full = np.nonzero(np.repeat(~mesh.fixed, 2))[0]
    restrict = lambda A: sp.csr_matrix(A)[free_full][:, free_full]  # noqa: E731
    Ks = [restrict(K) for K in U.K_layers]
    D1, M1 = restrict(U.D1), restrict(U.M1)
    graph = sp.csr_matrix(abs(M1) + abs(D1) + sum(abs(K) for K in Ks))
    order = minimum_degree(graph)
    perm = lambda A: sp.csr_matrix(A[order][:, order])  # noqa: E731
    pattern = perm(graph)
    pattern.sort_indices()
    k_vals = np.stack([_on_pattern(perm(K), pattern) for K in Ks])
    d_vals = _on_pattern(perm(D1), pattern)
    m_vals = _on_pattern(perm(M1), pattern)
    Lp, Lj = cholesky_pattern(pattern)
    ep_vals = np.stack([_on_pattern(perm(restrict(Ke)), pattern) for Ke in membrane_unit(mesh)])
    dofs = free_full[order]
    where = -np.ones(2 * mesh.n_nodes, dtype=np.int64)
    where[dofs] = np.arange(dofs.size)
    s = mesh.surface
    return System(
        mesh=mesh,
        nu=nu,
        dofs=dofs,
        indptr=pattern.indptr.astype(np.int64),
        indices=pattern.indices.astype(np.int64),
        k_vals=k_vals,
        d_vals=d_vals,
        m_vals=m_vals,
        Lp=Lp,
        Lj=Lj,
        sdx=where[2 * s],
        sdz=where[2 * s + 1],
        sX=mesh.points[s, 0].copy(),
        sZ=mesh.points[s, 1].copy(),
        ep_vals=ep_vals,
        element=element,
    )


@lru_cache(maxsize=16)
def get_system(mesh_name: str, nu: float, element: str = "p1") -> System:
    return build_system(load_mesh(mesh_name), nu, element)
