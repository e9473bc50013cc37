"""GPU ensemble backend (issue 38): simulations/s on the CUDA backend against the CPU lock-step kernel on all
cores of the same machine, in one run, and how far their GAWs are apart.

    python benchmarks/bench_gpu.py [--sizes 1000,8000,50000] [--e2e-sizes 1000,8000] [--cpu-n 512]
                                   [--workers N] [--is-n 2000] [--budget-s 270] [--quick]

Prints, for the paper's numerics (medium mesh, dt 5e-5 s, 550 ms; SimConfig() defaults) and prior draws from
the paper's ranges:
  * CPU lock-step: simulations/s with ``--workers`` processes (default: every core), blocks of 32;
  * agreement: GPU against CPU on the CPU's draws: same ``ok`` flags, max |dGAW| (mm^2), bit-identical count;
  * GPU integration alone (set-up done, outputs left on the GPU) for each of ``--sizes``: simulations/s, and
    the launch size the GPU's memory allowed; draws beyond ``--distinct`` repeat (the set-up of 50,000 draws on
    one core would take most of the budget);
  * GPU end to end (set-up, transfers, integration, results) for each of ``--e2e-sizes``, per phase;
  * importance sampling of a Table-3 recording end to end (draws, GPU evaluation, scoring, reduction) with
    ``--is-n`` draws, and the 50,000-draw time extrapolated from it when --is-n is smaller;
  * GPU memory one launch allocates, and the memory-bound limit from the bytes each step must move.
Sizes whose predicted time would overrun ``--budget-s`` are skipped with a line saying so. Without a GPU the
GPU part is skipped with the reason. ``--quick``: coarse mesh, 40 ms, small sizes (a check of this script,
e.g. with NUMBA_ENABLE_CUDASIM=1).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from vfcore import TABLE3, SimConfig  # noqa: E402
from vfcore.batch import prepare_block, simulate_group_cuda, simulate_many  # noqa: E402
from vfcore.params import Params  # noqa: E402

LO = np.array([9.0, 250.0, 0.5, 400.0, 950.0, 1.0, 7.4])  # paper priors, paper units
HI = np.array([15.0, 950.0, 3.0, 1800.0, 1200.0, 7.0, 8.4])
CPU_BLOCK = 32
#: H100 SXM HBM3 bandwidth, B/s, where the device's attributes cannot be read
H100_BANDWIDTH = 3.35e12


def _cpu_chunk(rows: np.ndarray, cfg: SimConfig):
    """One worker's share of the CPU baseline: (ok, message, gaw) per row."""
    return [(r.ok, r.message, r.gaw if r.ok else None) for r in simulate_many(rows, cfg, block=CPU_BLOCK)]


def cpu_baseline(P: np.ndarray, cfg: SimConfig, workers: int):
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    chunks = [P[i : i + CPU_BLOCK] for i in range(0, len(P), CPU_BLOCK)]
    # spawn: the children never inherit a CUDA context
    with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as ex:
        list(ex.map(_cpu_chunk, [P[:2]] * workers, [cfg.replace(duration=cfg.dt * 4, discard=0.0)] * workers))
        t = time.perf_counter()
        out = [r for part in ex.map(_cpu_chunk, chunks, [cfg] * len(chunks)) for r in part]
        dt = time.perf_counter() - t
    return out, dt


def bytes_per_step(system) -> tuple[int, int]:
    """(lower, upper) bytes one sample's step moves through GPU memory: the per-sample matrix values (K, M, D
    once, the factor twice: forward and back substitution) alone, and with the vectors they multiply (gathered
    once per entry) and the state and work vectors (about 20 n-vector reads and writes)."""
    nnz, nl, n, m = system.indices.size, system.nnz_factor, system.n, system.sdx.size
    lower = 8 * (3 * nnz + 2 * nl)
    upper = 8 * (6 * nnz + 4 * nl + 20 * n + 10 * m)
    return lower, upper


def bandwidth() -> tuple[float, str]:
    try:
        from numba import cuda

        dev = cuda.get_current_device()
        clock_khz = dev.MEMORY_CLOCK_RATE
        bus_bits = dev.GLOBAL_MEMORY_BUS_WIDTH
        return 2.0 * clock_khz * 1e3 * bus_bits / 8.0, "from the device's memory clock and bus width"
    except Exception:  # noqa: BLE001 - the attribute names differ between numba's CUDA targets
        return H100_BANDWIDTH, "the H100 SXM's; the device's attributes were not readable"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="1000,8000,50000")
    ap.add_argument("--e2e-sizes", default="1000,8000")
    ap.add_argument("--cpu-n", type=int, default=512)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--distinct", type=int, default=8192)
    ap.add_argument("--is-n", type=int, default=2000)
    ap.add_argument("--budget-s", type=float, default=270.0)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    t_start = time.perf_counter()
    cfg = SimConfig()
    if args.quick:
        cfg = SimConfig(mesh="coarse", duration=0.04, discard=0.0)
    sizes = [int(x) for x in args.sizes.split(",") if x]
    e2e_sizes = [int(x) for x in args.e2e_sizes.split(",") if x]
    n_draw = max([args.cpu_n, args.distinct] + e2e_sizes)
    P = LO + (HI - LO) * np.random.default_rng(0).random((n_draw, 7))
    P = np.array([Params.from_array(r).as_array() for r in P])
    n_steps = int(round(cfg.duration / cfg.dt))
    print(
        f"== GPU ensemble backend: mesh {cfg.mesh}, dt {cfg.dt:g} s, {cfg.duration * 1e3:g} ms ({n_steps} steps), "
        f"contact {cfg.contact}, early_stop {cfg.early_stop} =="
    )

    # CPU lock-step on every core first: the pool's children are spawned before this process touches CUDA
    simulate_many(P[:2], cfg.replace(duration=cfg.dt * 4, discard=0.0), block=2)  # compile / load the caches once
    cpu, t_cpu = cpu_baseline(P[: args.cpu_n], cfg, args.workers)
    rate_cpu = args.cpu_n / t_cpu
    print(
        f"CPU lock-step, {args.workers} processes, block {CPU_BLOCK}: {args.cpu_n} simulations in {t_cpu:.1f} s "
        f"= {rate_cpu:.1f} simulations/s ({sum(r[0] for r in cpu)} ok)"
    )

    from vfcore.gpu import cuda_status, integrate_cuda, is_simulator, max_launch
    from vfcore.solver.system import get_system

    system = get_system(cfg.mesh, cfg.nu, cfg.element)
    lo_b, hi_b = bytes_per_step(system)
    ok, what = cuda_status()
    if not ok:
        print(f"GPU: skipped: {what}")
        print(
            f"bytes per step and sample: {lo_b / 1e3:.0f} kB (matrix and factor values) to {hi_b / 1e3:.0f} kB "
            f"(with the vectors); at {H100_BANDWIDTH / 1e12:.2f} TB/s the memory-bound limit is "
            f"{H100_BANDWIDTH / (hi_b * n_steps):.0f}-{H100_BANDWIDTH / (lo_b * n_steps):.0f} simulations/s"
        )
        return
    print(f"GPU: {what}")

    t = time.perf_counter()
    simulate_many(P[:2], cfg.replace(duration=cfg.dt * 4, discard=0.0), device="cuda")
    print(f"kernel compilation and first launch: {time.perf_counter() - t:.1f} s")

    # agreement, end to end on the CPU's draws
    tim: dict = {}
    t = time.perf_counter()
    gpu = simulate_group_cuda([Params.from_array(r) for r in P[: args.cpu_n]], [cfg] * args.cpu_n, timings=tim)
    t_agree = time.perf_counter() - t
    same_ok = sum(a[0] == b.ok for a, b in zip(cpu, gpu))
    both = [(a[2], b.gaw) for a, b in zip(cpu, gpu) if a[0] and b.ok]
    dmax = max((float(np.max(np.abs(x - y))) for x, y in both), default=0.0)
    ident = sum(np.array_equal(x, y) for x, y in both)
    print(
        f"agreement on {args.cpu_n} draws: same ok flag {same_ok}/{args.cpu_n}, max |dGAW| {dmax:.3g} mm^2, "
        f"bit-identical GAW {ident}/{len(both)} (GPU end to end {args.cpu_n / t_agree:.1f} simulations/s)"
    )

    # the integration alone
    d = min(args.distinct, len(P))
    t = time.perf_counter()
    blk = prepare_block([Params.from_array(r) for r in P[:d]], [cfg] * d)
    setup_each = (time.perf_counter() - t) / d
    nmod = blk.sub_coef.shape[1]
    projection = cfg.contact != "layer"
    cap_dev = max_launch(system, n_steps, nmod, blk.n_traj, projection, host=False)
    cap_host = max_launch(system, n_steps, nmod, blk.n_traj, projection)
    print(
        f"set-up on the CPU: {setup_each * 1e3:.2f} ms per draw (one core); one launch holds at most {cap_dev} "
        f"samples (GPU memory), {cap_host} when the outputs come back (host memory)"
    )
    rate = None
    used = 0
    for size in sizes:
        left = args.budget_s - (time.perf_counter() - t_start)
        if rate is not None and size / rate > 0.5 * left:
            print(
                f"integration, {size} simulations: skipped (predicted {size / rate:.0f} s, {left:.0f} s of the "
                f"budget left)"
            )
            continue
        sel = np.arange(size) % d
        tk: dict = {}
        t = time.perf_counter()
        for lo in range(0, size, cap_dev):
            integrate_cuda(blk, sel[lo : lo + cap_dev], tk, fetch=False)
        dt = time.perf_counter() - t
        rate = size / tk["kernel_s"]
        used = max(used, tk["device_bytes"])
        print(
            f"integration, {size} simulations ({-(-size // cap_dev)} launches, {min(size, d)} distinct draws): "
            f"{rate:.0f} simulations/s on the GPU, {size / dt:.0f} with the uploads"
        )

    for size in e2e_sizes:
        left = args.budget_s - (time.perf_counter() - t_start)
        per = t_agree / args.cpu_n
        if size * per > 0.6 * left:
            print(f"end to end, {size} simulations: skipped (predicted {size * per:.0f} s, {left:.0f} s left)")
            continue
        tim = {}
        t = time.perf_counter()
        simulate_group_cuda([Params.from_array(r) for r in P[:size]], [cfg] * size, timings=tim)
        dt = time.perf_counter() - t
        used = max(used, tim["device_bytes"])
        ph = ", ".join(f"{k[:-2]} {v / size * 1e3:.2f}" for k, v in tim.items() if k.endswith("_s"))
        print(f"end to end, {size} simulations: {size / dt:.0f} simulations/s ({dt:.1f} s; ms per simulation: {ph})")

    # importance sampling of a Table-3 recording, end to end
    left = args.budget_s - (time.perf_counter() - t_start)
    per = t_agree / args.cpu_n
    if args.is_n * per * 1.5 > left:
        print(
            f"importance sampling, n={args.is_n}: skipped (predicted {args.is_n * per * 1.5:.0f} s, {left:.0f} s left)"
        )
    else:
        from vfcore.inference import Prior, Problem
        from vfcore.inference.device_eval import DeviceEvaluator
        from vfcore.inference.importance import draw_prior, map_evaluate, reduce_importance

        is_cfg = cfg.replace(duration=0.12, discard=0.02) if args.quick else cfg
        truth = simulate_many(np.array([TABLE3.as_array()]), is_cfg)[0]
        # a recording two thirds as long as the kept simulation, so every draw can be aligned to it
        obs = truth.gaw[: 2 * truth.gaw.size // 3]
        obs = obs + 0.05 * np.random.default_rng(1).standard_normal(obs.size)
        prior = Prior.default()
        pb = Problem(obs, cfg.fps, prior, sigma_e=0.05, config=is_cfg)
        t = time.perf_counter()
        th = draw_prior(prior, args.is_n, 0)
        ev = map_evaluate(DeviceEvaluator(pb, "cuda"), th, chunk_size=args.is_n)
        t_ev = time.perf_counter() - t
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # a small ensemble is degenerate; its cost is the point
                reduce_importance(th, ev, prior.names, 0, obs_gaw=pb.obs_compared, fps=pb.fps)
            red = f"reduction {time.perf_counter() - t - t_ev:.1f} s"
        except ImportError as exc:
            red = f"reduction not run ({exc})"
        t_red = time.perf_counter() - t - t_ev
        line = (
            f"importance sampling, n={args.is_n}, {prior.ndim} parameters: {t_ev + t_red:.1f} s end to end "
            f"(evaluation {t_ev:.1f} s, {red}; {int(ev.ok.sum())} ok)"
        )
        if args.is_n < 50_000:
            line += f"; n=50,000 extrapolated (evaluation linear in n): {t_ev * 50_000 / args.is_n + t_red:.0f} s"
        print(line)
    print("default 3-parameter diagnosis: not run (vfcore.diagnose has no device option yet)")

    bw, how = bandwidth()
    print(f"GPU memory of the largest launch: {used / 2**30:.2f} GiB")
    print(
        f"bytes per step and sample: {lo_b / 1e3:.0f} kB (matrix and factor values) to {hi_b / 1e3:.0f} kB (with "
        f"the vectors); memory-bound limit at {bw / 1e12:.2f} TB/s ({how}): "
        f"{bw / (hi_b * n_steps):.0f}-{bw / (lo_b * n_steps):.0f} simulations/s"
    )
    if is_simulator():
        print("(numba's CUDA simulator: GPU figures are CPU timings of the simulator, not a GPU's)")
    print(f"total {time.perf_counter() - t_start:.0f} s")


if __name__ == "__main__":
    main()
