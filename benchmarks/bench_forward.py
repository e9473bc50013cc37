"""Cost of one forward simulation (Table 3, medium mesh, dt = 5e-5, 550 ms) and batch throughput.

Prints: the scalar ``simulate`` (median of --runs) split into set-up / time loop / post-processing;
per-step costs of the loop's two kernels (the CSR products and the sparse triangular solves)
measured in isolation, with counted flops; the lock-step batch kernel
(:func:`vfcore.batch.simulate_many`, SIMD across samples) in ms per simulation on one core for
several block sizes; and simulations per second on all cores (one lock-step worker per core).

Usage: OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_forward.py [--runs 5] [--blocks 8,16,32]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

from vfcore import TABLE3, SimConfig, simulate, simulate_batch  # noqa: E402
from vfcore import forward as fw  # noqa: E402
from vfcore.batch import simulate_many  # noqa: E402
from vfcore.solver import _kernels as kern  # noqa: E402
from vfcore.solver._batch_kernels import chol_solve_many  # noqa: E402
from vfcore.solver.system import get_system  # noqa: E402


@njit(cache=True)
def _products(n_rep, indptr, indices, kval, mval, dval, y1, y2, u, r):
    for k in range(n_rep):
        for i in range(r.size):
            s = 0.0
            for p in range(indptr[i], indptr[i + 1]):
                j = indices[p]
                s += mval[p] * y1[j] + dval[p] * y2[j] - kval[p] * u[j]
            r[i] = s
        y1[k % y1.size] += 1e-30


@njit(cache=True)
def _solves(n_rep, Lp, Lj, Lx, r):
    for k in range(n_rep):
        kern.chol_solve(Lp, Lj, Lx, r)
        r[k % r.size] += 1e-30


@njit(cache=True)
def _solves_many(n_rep, Lp, Lj, Lx, r):
    for k in range(n_rep):
        chol_solve_many(Lp, Lj, Lx, r)
        r[k % r.shape[0], 0] += 1e-30


def _rows(n: int) -> np.ndarray:
    """Table 3 with p_sub and E_cover spread by +-5 % (all oscillate)."""
    P = np.tile(TABLE3.as_array(), (n, 1))
    P[:, 3] *= np.linspace(0.95, 1.05, n)
    P[:, 1] *= np.linspace(1.05, 0.95, n)
    return P


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--blocks", default="8,16,32")
    ap.add_argument("--batch", type=int, default=64, help="rows for the all-core throughput")
    args = ap.parse_args()
    cfg = SimConfig()
    p = TABLE3
    system = get_system(cfg.mesh, cfg.nu)
    n_steps = int(round(cfg.duration / cfg.dt))
    simulate(p, cfg)  # JIT warm-up (numba cache)
    total, setup = [], []
    for _ in range(args.runs):
        t0 = time.perf_counter()
        r = simulate(p, cfg)
        total.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        fw.setup(p, cfg, system)
        setup.append(time.perf_counter() - t0)
    assert r.ok
    med = statistics.median
    n, nnz, nl, m = system.n, system.indices.size, system.nnz_factor, system.sdx.size
    # kernels in isolation (same data as the loop)
    K, D, M, u, Lx, G = fw.setup(p, cfg, system)
    rng = np.random.default_rng(0)
    y1, y2, uu, rr = (rng.standard_normal(n) for _ in range(4))
    _products(2, system.indptr, system.indices, K, M, D, y1, y2, uu, rr)
    _solves(2, system.Lp, system.Lj, Lx, rr)
    t0 = time.perf_counter()
    _products(n_steps, system.indptr, system.indices, K, M, D, y1, y2, uu, rr)
    t_prod = time.perf_counter() - t0
    t0 = time.perf_counter()
    _solves(n_steps, system.Lp, system.Lj, Lx, rr)
    t_solve = time.perf_counter() - t0
    us_step = med(total) / n_steps * 1e6
    flops_prod = 2 * 3 * nnz
    flops_solve = 2 * 2 * nl
    print(
        f"mesh {cfg.mesh}: n = {n} free dofs, CSR nnz {nnz}, Cholesky factor nnz {nl} "
        f"(minimum-degree order), surface nodes {m}; {n_steps} steps"
    )
    print(f"{'scalar simulate()':46s} value")
    for k, v in [
        ("simulate() 550 ms, dt 5e-5 (median ms)", f"{med(total) * 1e3:.1f}"),
        ("  set-up: prestress + factorisation + G (ms)", f"{med(setup) * 1e3:.2f}"),
        ("  us per step (whole loop)", f"{us_step:.2f}"),
        ("  CSR products M y1 + D y2 - K u, ms / 11k steps", f"{t_prod * 1e3:.1f}"),
        ("  two triangular solves, ms / 11k steps", f"{t_solve * 1e3:.1f}"),
        ("  rest (loads, contact, update), ms", f"{(med(total) - med(setup) - t_prod - t_solve) * 1e3:.1f}"),
        ("  flops per step (products + solves)", f"{flops_prod + flops_solve}"),
        (
            "  GFLOP/s products / solves",
            f"{flops_prod * n_steps / t_prod / 1e9:.2f} / {flops_solve * n_steps / t_solve / 1e9:.2f}",
        ),
        ("  working set per sample (KiB)", f"{(3 * nnz * 8 + nnz * 8 + nl * 16 + n * m * 8 + 6 * n * 8) / 1024:.0f}"),
    ]:
        print(f"{k:46s} {v}")
    print("lock-step batch (vfcore.batch.simulate_many), one core, Table 3 +- 5 %:")
    blocks = [int(b) for b in args.blocks.split(",")]
    simulate_many(_rows(2), cfg, block=2)
    for B in blocks:
        P = _rows(B)
        ts = []
        for _ in range(max(1, args.runs // 2)):
            t0 = time.perf_counter()
            res = simulate_many(P, cfg, block=B)
            ts.append((time.perf_counter() - t0) / B)
        assert all(x.ok for x in res)
        Lxb = np.repeat(Lx[:, None], B, axis=1)
        rb = rng.standard_normal((n, B))
        _solves_many(2, system.Lp, system.Lj, Lxb, rb)
        t0 = time.perf_counter()
        _solves_many(n_steps, system.Lp, system.Lj, Lxb, rb)
        ts_solve = (time.perf_counter() - t0) / B
        print(
            f"  block {B:3d}: {med(ts) * 1e3:6.1f} ms per simulation "
            f"(of which triangular solves {ts_solve * 1e3:5.1f} ms); {1 / med(ts):5.1f} sims/s per core"
        )
    ncpu = os.cpu_count() or 1
    P = _rows(args.batch)
    B = max(blocks)
    simulate_batch(P[: 2 * ncpu], cfg, n_workers=ncpu, block=2)  # warm the workers' JIT cache
    t0 = time.perf_counter()
    res_p = simulate_batch(P, cfg, n_workers=ncpu, block=B)
    t1 = time.perf_counter()
    assert all(x.ok for x in res_p)
    print(
        f"all cores: {args.batch} simulations on {ncpu} worker processes, block {B}: "
        f"{args.batch / (t1 - t0):.1f} sims/s (incl. process start-up)"
    )


if __name__ == "__main__":
    main()
