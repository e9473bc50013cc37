"""numba kernels of the time integration against dense linear algebra and hand-computed Bernoulli flow."""
import itertools

import numpy as np
import pytest
import scipy.sparse as sp

from vfcore.solver import _kernels as kern


def _random_spd_band(n, bw, rng):
    A = np.zeros((n, n))
    for k in range(1, bw + 1):
        d = rng.standard_normal(n - k)
        A += np.diag(d, k) + np.diag(d, -k)
    # strictly diagonally dominant -> SPD
    A += np.diag(np.abs(A).sum(axis=1) + 0.1 + rng.random(n))
    return A


def _to_band(A, bw):
    n = A.shape[0]
    Ab = np.zeros((n, bw + 1))
    for i in range(n):
        for j in range(max(0, i - bw), i + 1):
            Ab[i, j - i + bw] = A[i, j]
    return Ab


@pytest.mark.parametrize("n,bw", [(1, 0), (5, 1), (12, 4), (40, 7), (100, 29), (60, 59)])
def test_band_cholesky_and_solve_vs_dense(n, bw):
    rng = np.random.default_rng(n * 100 + bw)
    A = _random_spd_band(n, bw, rng)
    Lb = _to_band(A, bw)
    assert kern.band_cholesky(Lb) == 0
    L = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - bw), i + 1):
            L[i, j] = Lb[i, j - i + bw]
    np.testing.assert_allclose(L, np.linalg.cholesky(A), rtol=1e-12, atol=1e-12 * np.abs(A).max())
    for _ in range(3):
        b = rng.standard_normal(n)
        x = b.copy()
        kern.band_solve(Lb, x)
        np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-10, atol=1e-12)


def test_band_cholesky_reports_indefinite_minor():
    A = np.diag([4.0, 1.0, -1.0, 2.0])
    A[1, 0] = A[0, 1] = 0.5
    Lb = _to_band(A, 1)
    assert kern.band_cholesky(Lb) == 3      # leading minor of order 3 fails
    Lb = _to_band(np.diag([1.0, 0.0]), 0)
    assert kern.band_cholesky(Lb) == 2


@pytest.mark.parametrize("n,bw", [(10, 2), (50, 9)])
def test_csr_to_band_round_trip(n, bw):
    rng = np.random.default_rng(7)
    A = _random_spd_band(n, bw, rng)
    A[np.abs(A) < 0.3] = 0.0                 # sparsify, keep symmetry
    A = 0.5 * (A + A.T)
    C = sp.csr_matrix(A)
    C.sort_indices()
    out = np.full((n, bw + 1), 123.0)        # garbage must be overwritten
    kern.csr_to_band(C.indptr.astype(np.int64), C.indices.astype(np.int64), C.data, n, bw, out)
    back = np.zeros((n, n))
    for i in range(n):
        for k in range(bw + 1):
            j = i - bw + k
            if j >= 0:
                back[i, j] = out[i, k]
            else:
                assert out[i, k] == 0.0
    full = np.tril(back) + np.tril(back, -1).T
    np.testing.assert_array_equal(full, A)


def _loads(gap, p_sub, p_sup, sep=1.3, tol=1e-9, nx=None, nz=None):
    m = len(gap)
    gap = np.asarray(gap, dtype=float)
    nx = np.zeros(m) if nx is None else np.asarray(nx, float)
    nz = np.linspace(0, 1e-2, m) if nz is None else np.asarray(nz, float)
    fx, fz, pres = np.empty(m), np.empty(m), np.empty(m)
    out = kern.surface_loads(nx.copy(), nz.copy(), nx, nz, gap, p_sub, p_sup, sep, tol, 0.0, fx, fz, pres)
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
    nz = np.sort(np.r_[0.0, np.random.default_rng(m).uniform(0, Lw, m - 2), Lw])   # uneven spacing
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
    sdx = np.array([0, 2, 4, -1, 6], dtype=np.int64)      # one fixed surface node
    sX = np.array([0.9, 1.0, 1.05, 1.2, 0.95])
    x_mid = 1.0
    f = rng.standard_normal(n) * 3.0
    f[sdx[sdx >= 0]] += 4.0                               # push towards the midline
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
    assert np.all(lam <= 0.0)                       # compressive only
    assert np.any(lam < 0.0)                        # the case does press on the midline
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
    u = np.full(K.shape[0], -1.0)                   # everything far from the midline
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
