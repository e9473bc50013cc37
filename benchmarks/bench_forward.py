"""Cost of one forward simulation (Table 3, medium mesh, dt = 5e-5, 550 ms) and batch throughput.

Usage: OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_forward.py [--runs 20]
"""
from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from vfcore import TABLE3, SimConfig, simulate, simulate_batch  # noqa: E402
from vfcore import forward as fw  # noqa: E402
from vfcore.solver import _kernels as kern  # noqa: E402
from vfcore.solver.system import get_system  # noqa: E402


def _setup(system, p, cfg):
    si = p.si()
    K_vals = system.stiffness_values((si["E_body"], si["E_lig"], si["E_cover"]))
    u, _ = fw.prestress(system, K_vals, fw.midline(p, cfg))
    cM, cD, cK = kern.effective_scales(cfg.dt, cfg.rho_inf)
    Lb = system.factor(cK * K_vals + cD * si["eta"] * system.d_vals + cM * si["rho"] * system.m_vals)
    G = system.contact_columns(Lb)
    return K_vals, u, Lb, G


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--batch", type=int, default=64)
    args = ap.parse_args()
    cfg = SimConfig()
    p = TABLE3
    system = get_system(cfg.mesh, cfg.nu)
    n_steps = int(round(cfg.duration / cfg.dt))
    simulate(p, cfg)                                   # JIT warm-up (numba cache)
    total, setup, loop = [], [], []
    for _ in range(args.runs):
        t0 = time.perf_counter()
        simulate(p, cfg)
        total.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        K_vals, u, Lb, G = _setup(system, p, cfg)
        t1 = time.perf_counter()
        si = p.si()
        am, af, beta, gamma = kern.newmark_coefficients(cfg.dt, cfg.rho_inf)
        m = system.sdx.size
        kern.integrate(n_steps, cfg.dt, am, af, beta, gamma, system.indptr, system.indices, K_vals,
                       si["rho"] * system.m_vals, si["eta"] * system.d_vals, Lb, G, system.sdx, system.sdz,
                       system.sX, system.sZ, u, np.zeros(system.n), np.zeros(system.n), si["p_sub"], cfg.p_sup,
                       cfg.sep_ratio, fw.midline(p, cfg), fw.CLOSED_TOL, cfg.closure_gap_mm * 1e-3, fw.BLOWUP,
                       np.zeros(n_steps),
                       np.zeros(n_steps), np.zeros((n_steps, m)), 0, np.zeros((0, system.n)),
                       np.zeros((0, system.n)))
        t2 = time.perf_counter()
        setup.append(t1 - t0)
        loop.append(t2 - t1)
    med = statistics.median
    n, bw, nnz = system.n, system.bw, system.indices.size
    flops_spmv = 2 * 3 * nnz                          # three matrices on one CSR pattern, multiply-add
    flops_solve = 4 * n * bw                          # forward + backward band substitution
    flops_step = flops_spmv + flops_solve
    us_step = med(loop) / n_steps * 1e6
    gflops = flops_step / (us_step * 1e-6) / 1e9
    ws = (3 * nnz * 8 + 2 * nnz * 8 // 2 + (n + 1) * 8   # values (3 arrays), int64 indices, indptr
          + n * (bw + 1) * 8                               # band factor
          + n * m * 8                                      # contact columns G
          + 6 * n * 8)                                     # u, v, a, y1, y2, r
    print(f"mesh {cfg.mesh}: n = {n} free dofs, half bandwidth {bw}, CSR nnz {nnz}, surface nodes {m}")
    print(f"{'quantity':44s} value")
    rows = [
        ("simulate() 550 ms, dt 5e-5 (median ms)", f"{med(total) * 1e3:.1f}"),
        ("  setup: prestress + factorisation + G (ms)", f"{med(setup) * 1e3:.2f}"),
        ("  time loop (ms)", f"{med(loop) * 1e3:.1f}"),
        ("  post-processing / downsampling (ms)", f"{(med(total) - med(setup) - med(loop)) * 1e3:.1f}"),
        ("steps", f"{n_steps}"),
        ("us per step", f"{us_step:.2f}"),
        ("flops per step (3 SpMV + band solve)", f"{flops_step}"),
        ("achieved GFLOP/s (counted flops)", f"{gflops:.2f}"),
        ("per-step working set (KiB)", f"{ws / 1024:.0f}"),
    ]
    for k, v in rows:
        print(f"{k:44s} {v}")
    ncpu = os.cpu_count() or 1
    P = np.tile(TABLE3.as_array(), (args.batch, 1))
    P[:, 3] *= np.linspace(0.8, 1.2, args.batch)       # vary p_sub
    simulate_batch(P[:ncpu], cfg, n_workers=ncpu)      # warm the pool's JIT cache
    t0 = time.perf_counter()
    res = simulate_batch(P, cfg, n_workers=1)
    t1 = time.perf_counter()
    res_p = simulate_batch(P, cfg, n_workers=ncpu)
    t2 = time.perf_counter()
    assert all(r.ok for r in res) and all(r.ok for r in res_p)
    print(f"batch of {args.batch}: serial {args.batch / (t1 - t0):.1f} sims/s; "
          f"{ncpu} workers {args.batch / (t2 - t1):.1f} sims/s (incl. process start-up)")


if __name__ == "__main__":
    main()
