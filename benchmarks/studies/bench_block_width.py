"""Lock-step block width: seconds for ``simulate_many`` to run N rows in one block against the same rows in
narrower blocks, one core, rows near Table 3 (each of the six material parameters times exp(N(0, 0.05²)), seed 0).
Prints the median of --reps runs per case; the basis of ``vfcore.batch.LOCKSTEP_WIDTH``. Run it with a core to
itself.

    OMP_NUM_THREADS=1 python benchmarks/studies/bench_block_width.py [--reps 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402

from vfcore import SimConfig  # noqa: E402
from vfcore.batch import simulate_many  # noqa: E402
from vfcore.params import TABLE3  # noqa: E402

#: (mesh, dt, rows, block widths compared)
CASES = [
    ("medium", 5e-5, 40, (40, 20)),
    ("medium", 5e-5, 48, (48, 24)),
    ("medium", 5e-5, 50, (50, 32)),
    ("medium", 5e-5, 64, (64, 32)),
    ("medium", 5e-5, 100, (100, 50)),
    ("coarse", 1e-4, 64, (64, 32)),
    ("coarse", 1e-4, 100, (100, 50)),
]
NAMES = ("E_body", "E_cover", "E_lig", "p_sub", "rho", "eta")


def rows(n: int):
    rng = np.random.default_rng(0)
    return [
        TABLE3.replace(**{k: getattr(TABLE3, k) * f for k, f in zip(NAMES, np.exp(rng.normal(0, 0.05, 6)))})
        for _ in range(n)
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=3)
    a = ap.parse_args()
    R = rows(max(n for *_, n, _ in CASES))
    for mesh, dt in sorted({(m, d) for m, d, *_ in CASES}):
        cfg = SimConfig(mesh=mesh, dt=dt)
        simulate_many(R[:2], cfg.replace(duration=dt * 4, discard=0.0), block=2)  # load the compiled kernels
    print("mesh    dt       rows  block  median s  ms/sim  (runs)")
    for mesh, dt, n, widths in CASES:
        cfg = SimConfig(mesh=mesh, dt=dt)
        for b in widths:
            ts = []
            for _ in range(a.reps):
                t0 = time.perf_counter()
                simulate_many(R[:n], cfg, block=b)
                ts.append(time.perf_counter() - t0)
            med = statistics.median(ts)
            print(
                f"{mesh:<7} {dt:<8g} {n:>4}  {b:>5}  {med:8.2f}  {1000 * med / n:6.1f}  "
                f"({', '.join(f'{t:.2f}' for t in ts)})",
                flush=True,
            )


if __name__ == "__main__":
    main()
