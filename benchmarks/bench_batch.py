"""Batched forward model: ms per 550-ms simulation (11,000 steps at dt = 5e-5) for block
sizes 1, 4, 8, 16 versus the scalar ``simulate``, one core. Prints medians of --reps runs.

    OMP_NUM_THREADS=1 python benchmarks/bench_batch.py [--n 16] [--reps 3]
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
from vfcore.batch import simulate_many  # noqa: E402

LO = np.array([9.0, 250.0, 0.5, 400.0, 950.0, 1.0, 7.4])
HI = np.array([15.0, 950.0, 3.0, 1800.0, 1200.0, 7.0, 8.4])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=16)
    ap.add_argument("--reps", type=int, default=3)
    args = ap.parse_args()
    P = LO + (HI - LO) * np.random.default_rng(0).random((args.n, 7))
    cfg = SimConfig()
    simulate(P[0], cfg)
    simulate_many(P[:2], cfg, block=2)       # compile / load caches

    def per_sim(fn) -> float:
        ts = []
        for _ in range(args.reps):
            t = time.perf_counter()
            fn()
            ts.append((time.perf_counter() - t) / len(P) * 1e3)
        return statistics.median(ts)

    print("== batched forward model (ms per simulation, median) ==")
    print(f"scalar simulate : {per_sim(lambda: [simulate(p, cfg) for p in P]):8.1f} ms")
    for block in (1, 4, 8, 16):
        print(f"block {block:2d}        : {per_sim(lambda: simulate_many(P, cfg, block=block)):8.1f} ms")


if __name__ == "__main__":
    main()
