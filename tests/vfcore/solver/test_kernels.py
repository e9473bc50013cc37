"""numba kernels of the time integration against dense linear algebra and hand-computed Bernoulli flow."""

import itertools

import numpy as np
import pytest
import scipy.sparse as sp

from vfcore.solver import _kernels as kern
from vfcore.solver._batch_kernels import chol_solve_many
from vfcore.solver.system import cholesky_pattern, minimum_degree


def _random_sparse_spd(n, density, rng):
    """Random symmetric, strictly diagonally dominant (hence SPD) sparse matrix, as CSR."""
    A = sp.random(n, n, density=density, random_state=rng, data_rvs=rng.standard_normal).toarray()
    A = A + A.T
    A += np.diag(np.abs(A).sum(axis=1) + 0.1 + rng.random(n))
    C = sp.csr_matrix(A)
    C.sort_indices()
    return A, C


def _dense_symbolic(C):
    """Fill pattern by eliminating a dense boolean matrix column by column: O(n^2) memory, the oracle."""
    n = C.shape[0]
    S = np.tril(C.toarray() != 0) | np.eye(n, dtype=bool)
    for k in range(n):
        rows = np.nonzero(S[k + 1 :, k])[0] + k + 1
        S[np.ix_(rows, rows)] |= np.tril(np.ones((rows.size, rows.size), dtype=bool))
    return S


def _brute_minimum_degree(C):
    """Eliminate the least-degree live vertex (lowest index on ties) found by scanning all of them."""
    n = C.shape[0]
    adj = [set(C.indices[C.indptr[i] : C.indptr[i + 1]].tolist()) - {i} for i in range(n)]
    alive, order = set(range(n)), []
    while alive:
        v = min(alive, key=lambda i: (len(adj[i]), i))
        for w in adj[v]:
            adj[w] = (adj[w] | adj[v]) - {w, v}
        alive.remove(v)
        order.append(v)
    return order


@pytest.mark.parametrize("n,density", [(1, 1.0), (7, 0.3), (30, 0.1), (80, 0.04), (150, 0.02), (60, 0.4)])
def test_symbolic_factor_and_ordering_match_the_dense_elimination(n, density):
    """The elimination-tree pattern is exactly the dense elimination's fill, row by row, and the heap's
    minimum-degree order is the scan's, tie for tie, on random structurally symmetric patterns."""
    rng = np.random.default_rng(7 * n + int(1000 * density))
    _, C = _random_sparse_spd(n, density, rng)
    order = minimum_degree(C)
    assert order.tolist() == _brute_minimum_degree(C)
    for perm in (np.arange(n), order, rng.permutation(n)):
        Cp = sp.csr_matrix(C[perm][:, perm])
        Cp.sort_indices()
        Lp, Lj = cholesky_pattern(Cp)
        S = _dense_symbolic(Cp)
        assert Lp[-1] == S.sum()
        for i in range(n):
            assert Lj[Lp[i] : Lp[i + 1]].tolist() == np.nonzero(S[i])[0].tolist()


@pytest.mark.parametrize("n,density", [(1, 1.0), (5, 0.3), (12, 0.2), (40, 0.08), (100, 0.03), (60, 0.5)])
def test_sparse_cholesky_and_solve_vs_dense(n, density):
    rng = np.random.default_rng(n * 100 + int(100 * density))
    A, C = _random_sparse_spd(n, density, rng)
    order = minimum_degree(C)
    assert sorted(order.tolist()) == list(range(n))  # a permutation
    Cp = sp.csr_matrix(C[order][:, order])
    Cp.sort_indices()
    Ap = A[np.ix_(order, order)]
    Lp, Lj = cholesky_pattern(Cp)
    L_dense = np.linalg.cholesky(Ap)
    # the symbolic pattern holds every structural nonzero of the dense factor, diagonal last
    S = np.zeros((n, n), dtype=bool)
    for i in range(n):
        cols = Lj[Lp[i] : Lp[i + 1]]
        assert cols[-1] == i and np.all(np.diff(cols) > 0)
        S[i, cols] = True
    assert not np.any((np.abs(L_dense) > 1e-14 * np.abs(L_dense).max()) & ~S)
    Lx = np.empty(Lj.size)
    ip, ix = Cp.indptr.astype(np.int64), Cp.indices.astype(np.int64)
    assert kern.sparse_cholesky(ip, ix, Cp.data, Lp, Lj, Lx) == 0
    L = np.zeros((n, n))
    for i in range(n):
        for q in range(Lp[i], Lp[i + 1]):
            L[i, Lj[q]] = Lx[q] if Lj[q] != i else 1.0 / Lx[q]  # diagonal stored as 1 / L_ii
    np.testing.assert_allclose(L, L_dense, rtol=1e-12, atol=1e-12 * np.abs(A).max())
    B = 5
    rhs = rng.standard_normal((n, B))
    X = rhs.copy()
    chol_solve_many(Lp, Lj, np.repeat(Lx[:, None], B, axis=1), X)  # batched: every column
    for b in range(B):
        x = rhs[:, b].copy()
        kern.chol_solve(Lp, Lj, Lx, x)
        np.testing.assert_allclose(x, np.linalg.solve(Ap, rhs[:, b]), rtol=1e-10, atol=1e-12)
        assert np.array_equal(X[:, b], x)  # same operations in the same order


def test_sparse_cholesky_reports_indefinite_minor():
    A = np.diag([4.0, 1.0, -1.0, 2.0])
    A[1, 0] = A[0, 1] = 0.5
    C = sp.csr_matrix(A)
    Lp, Lj = cholesky_pattern(C)
    Lx = np.empty(Lj.size)
    args = (C.indptr.astype(np.int64), C.indices.astype(np.int64), C.data, Lp, Lj, Lx)
    assert kern.sparse_cholesky(*args) == 3  # leading minor of order 3 fails
    C = sp.csr_matrix(np.diag([1.0, 0.0]))
    Lp, Lj = cholesky_pattern(C)
    Lx = np.empty(Lj.size)
    assert kern.sparse_cholesky(C.indptr.astype(np.int64), C.indices.astype(np.int64), C.data, Lp, Lj, Lx) == 2


def test_minimum_degree_reduces_fill_on_the_fold_meshes():
    """The factor pattern of the shipped meshes is smaller than the reverse Cuthill-McKee band."""
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    from vfcore.solver.system import get_system

    for mesh in ("coarse", "medium", "fine"):
        s = get_system(mesh, 0.4995)
        pat = s.matrix(np.ones(s.indices.size))
        rcm = reverse_cuthill_mckee(pat, symmetric_mode=True)
        P = pat[rcm][:, rcm].tocoo()
        band = s.n * (int(np.max(np.abs(P.row - P.col))) + 1)
        assert s.nnz_factor < 0.6 * band


def _loads(gap, p_sub, p_sup, sep=1.3, tol=1e-9, nx=None, nz=None):
    m = len(gap)
    gap = np.asarray(gap, dtype=float)
    nx = np.zeros(m) if nx is None else np.asarray(nx, float)
    nz = np.linspace(0, 1e-2, m) if nz is None else np.asarray(nz, float)
    fx, fz, pres = np.empty(m), np.empty(m), np.empty(m)
    out = kern.surface_loads(
        nx.copy(), nz.copy(), nx, nz, gap, p_sub, p_sup, sep, tol, 0.0, fx, fz, pres, kern.FLOW_PAPER
    )
    return out, pres, fx, fz


def test_surface_loads_open_channel_bernoulli():
    mm = 1e-3
    gap = np.array([5, 4, 3, 2, 1, 1.2, 1.5, 2, 3]) * mm
    p_sub, p_sup = 1000.0, 50.0
    (gmin, gsep, iclose), pres, _, _ = _loads(gap, p_sub, p_sup)
    assert iclose == -1
    assert gmin == pytest.approx(1 * mm)
    assert gsep == pytest.approx(1.3 * mm)
    # separation at the first node downstream of the minimum whose gap reaches 1.3 mm: index 6
    dp = p_sub - p_sup
    for i in range(6):
        assert pres[i] == pytest.approx(p_sub - dp * (1.3 / (gap[i] / mm)) ** 2, rel=1e-12)
    assert np.all(pres[6:] == p_sup)
    # at the minimum the jet has its full Bernoulli suction: p = p_sub - 1.69 dp
    assert pres[4] == pytest.approx(p_sub - 1.69 * dp)


def test_surface_loads_closed_glottis():
    gap = np.array([3e-3, 2e-3, 0.0, 0.0, 1e-3, 2e-3])
    (gmin, gsep, iclose), pres, _, _ = _loads(gap, 800.0, 20.0)
    assert iclose == 2 and gsep == 0.0 and gmin == 0.0
    np.testing.assert_array_equal(pres, [800.0, 800.0, 20.0, 20.0, 20.0, 20.0])


@pytest.mark.parametrize("m", [2, 7, 30])
def test_surface_loads_net_force_on_vertical_wall(m):
    """Uniform pressure p on a straight wall x = const, z in [0, Lw] (traversed upwards):
    the nodal forces sum to -p Lw in x (into the fold, which lies at smaller x) and 0 in z."""
    Lw = 4e-3
    nz = np.linspace(0.0, Lw, m) ** 1.0
    nz = np.sort(np.r_[0.0, np.random.default_rng(m).uniform(0, Lw, m - 2), Lw])  # uneven spacing
    nx = np.full(m, 8.4e-3)
    # closed at the first node -> p_sup everywhere
    (_, _, iclose), pres, fx, fz = _loads(np.zeros(m), 900.0, 333.0, nx=nx, nz=nz)
    assert iclose == 0 and np.all(pres == 333.0)
    assert fx.sum() == pytest.approx(-333.0 * Lw, rel=1e-12)
    assert abs(fz.sum()) < 1e-15
    # open with uniform gap -> uniform p = p_sub - 1.69 dp everywhere (no separation point)
    (_, _, _), pres, fx, fz = _loads(np.full(m, 1e-4), 900.0, 0.0, nx=nx, nz=nz)
    p = 900.0 * (1 - 1.69)
    np.testing.assert_allclose(pres, p)
    assert fx.sum() == pytest.approx(-p * Lw, rel=1e-12)
    # a tilted straight wall: the force is p * length along the inward normal
    ang = 0.7
    s = np.linspace(0, Lw, m)
    nx2, nz2 = 1e-3 + s * np.sin(ang), s * np.cos(ang)
    _, pres, fx, fz = _loads(np.zeros(m), 900.0, 333.0, nx=nx2, nz=nz2)
    assert fx.sum() == pytest.approx(-333.0 * Lw * np.cos(ang), rel=1e-12)
    assert fz.sum() == pytest.approx(333.0 * Lw * np.sin(ang), rel=1e-12)


def _tiny_contact_system(seed):
    rng = np.random.default_rng(seed)
    n = 8
    B = rng.standard_normal((n, n))
    K = B @ B.T + n * np.eye(n)
    sdx = np.array([0, 2, 4, -1, 6], dtype=np.int64)  # one fixed surface node
    sX = np.array([0.9, 1.0, 1.05, 1.2, 0.95])
    x_mid = 1.0
    f = rng.standard_normal(n) * 3.0
    f[sdx[sdx >= 0]] += 4.0  # push towards the midline
    u0 = np.linalg.solve(K, f)
    G = np.zeros((n, sdx.size))
    for j, d in enumerate(sdx):
        if d >= 0:
            G[:, j] = np.linalg.solve(K, np.eye(n)[d])
    return K, f, u0, G, sdx, sX, x_mid


def _brute_force(K, u0, sdx, sX, x_mid):
    """min 0.5 (u - u0)' K (u - u0) s.t. sX_j + u[sdx_j] <= x_mid, by enumerating active sets."""
    free = [j for j in range(sdx.size) if sdx[j] >= 0]
    best, best_u = np.inf, None
    n = K.shape[0]
    for r in range(len(free) + 1):
        for S in itertools.combinations(free, r):
            k = len(S)
            C = np.zeros((k, n))
            d = np.zeros(k)
            for a, j in enumerate(S):
                C[a, sdx[j]] = 1.0
                d[a] = x_mid - sX[j]
            KKT = np.block([[K, C.T], [C, np.zeros((k, k))]])
            sol = np.linalg.solve(KKT, np.r_[K @ u0, d])
            u = sol[:n]
            if all(sX[j] + u[sdx[j]] <= x_mid + 1e-12 for j in free):
                e = 0.5 * (u - u0) @ K @ (u - u0)
                if e < best:
                    best, best_u = e, u
    return best_u


@pytest.mark.parametrize("seed", range(6))
def test_contact_correct_matches_brute_force(seed):
    K, f, u0, G, sdx, sX, x_mid = _tiny_contact_system(seed)
    u = u0.copy()
    lam = np.zeros(sdx.size)
    active = np.zeros(sdx.size, dtype=np.bool_)
    it = kern.contact_correct(u, sdx, sX, x_mid, G, lam, active, 50)
    assert it >= 0
    free = sdx >= 0
    xs = sX[free] + u[sdx[free]]
    assert np.all(xs <= x_mid * (1 + 1e-12))
    assert np.all(lam <= 0.0)  # compressive only
    assert np.any(lam < 0.0)  # the case does press on the midline
    assert np.all(lam[~free] == 0.0)
    # complementarity: a multiplier only where the node touches the midline
    touching = np.abs(xs - x_mid) < 1e-12
    assert np.all(lam[free][~touching] == 0.0)
    # equilibrium: K u = f + sum_j lam_j e_{sdx_j}
    load = f.copy()
    for j in np.nonzero(free)[0]:
        load[sdx[j]] += lam[j]
    np.testing.assert_allclose(K @ u, load, atol=1e-10)
    np.testing.assert_allclose(u, _brute_force(K, u0, sdx, sX, x_mid), atol=1e-10)


def test_contact_correct_no_penetration_is_noop():
    K, f, u0, G, sdx, sX, x_mid = _tiny_contact_system(0)
    u = np.full(K.shape[0], -1.0)  # everything far from the midline
    ref = u.copy()
    lam = np.ones(sdx.size)
    active = np.ones(sdx.size, dtype=np.bool_)
    assert kern.contact_correct(u, sdx, sX, x_mid, G, lam, active, 50) == 0
    np.testing.assert_array_equal(u, ref)
    assert np.all(lam == 0.0) and not active.any()


def test_newmark_coefficients():
    am, af, beta, gamma = kern.newmark_coefficients(1e-4, 1.0)
    assert (am, af, beta, gamma) == (0.0, 0.0, 0.25, 0.5)
    # Chung-Hulbert: second order requires gamma = 1/2 - am + af, unconditional stability
    # beta = (1 - am + af)^2 / 4 and am <= af <= 1/2
    for r in (0.0, 0.5, 0.9):
        am, af, beta, gamma = kern.newmark_coefficients(1e-4, r)
        assert gamma == pytest.approx(0.5 - am + af)
        assert am <= af <= 0.5
        assert beta >= 0.5 * gamma - 1e-15
