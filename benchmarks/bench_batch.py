"""Batched forward model: ms per 550-ms simulation for the lock-step kernel at block sizes 1, 2, 3,
4, 6, 8, 16 versus the scalar ``simulate``, one core, and ``simulate_many`` itself (which sends blocks of
fewer than ``MIN_LOCKSTEP`` rows to the scalar kernel). Prints medians of --reps runs.

    OMP_NUM_THREADS=1 python benchmarks/bench_batch.py [--n 16] [--reps 3] [--mesh medium] [--dt 5e-5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from vfcore import SimConfig, simulate  # noqa: E402
from vfcore.batch import MIN_LOCKSTEP, _simulate_block, simulate_many  # noqa: E402
from vfcore.params import Params  # noqa: E402

LO = np.array([9.0, 250.0, 0.5, 400.0, 950.0, 1.0, 7.4])
HI = np.array([15.0, 950.0, 3.0, 1800.0, 1200.0, 7.0, 8.4])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=16)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--mesh", default="medium")
    ap.add_argument("--dt", type=float, default=5e-5)
    args = ap.parse_args()
    P = LO + (HI - LO) * np.random.default_rng(0).random((args.n, 7))
    cfg = SimConfig(mesh=args.mesh, dt=args.dt)
    ps = [Params.from_array(r) for r in P]
    simulate(P[0], cfg)
    _simulate_block(ps[:2], [cfg] * 2)  # compile / load caches

    def lockstep(block: int) -> None:
        for s in range(0, len(ps), block):
            _simulate_block(ps[s : s + block], [cfg] * len(ps[s : s + block]))

    def per_sim(fn) -> float:
        ts = []
        for _ in range(args.reps):
            t = time.perf_counter()
            fn()
            ts.append((time.perf_counter() - t) / len(P) * 1e3)
        return statistics.median(ts)

    print(f"== batched forward model, {args.mesh} mesh, dt {args.dt:g} s (ms per simulation, median) ==")
    scalar = per_sim(lambda: [simulate(p, cfg) for p in P])
    print(f"scalar simulate      : {scalar:8.1f} ms")
    for block in (1, 2, 3, 4, 6, 8, 16):
        t = per_sim(lambda: lockstep(block))
        print(f"lock-step block {block:2d}   : {t:8.1f} ms  ({t / scalar:.2f}x scalar)")
    print(
        f"simulate_many, block 32 (blocks under {MIN_LOCKSTEP} rows scalar): "
        f"{per_sim(lambda: simulate_many(P, cfg)):8.1f} ms"
    )


if __name__ == "__main__":
    main()
