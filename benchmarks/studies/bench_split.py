"""How a diagnosis's SMC generation is cut for the worker pool: wall time of one generation of
``--rows`` finite-element rows on a pool of ``--workers`` processes, in fixed chunks of
``n_particles / workers`` and of ``n_particles / (2 workers)`` rows at 40 base particles (what the
service and the command line cut without a balanced map) and in equal parts, one per worker
(:class:`vfcore.inference.importance.BalancedMap`). Every split gives the same log-likelihoods
(checked here, and in tests/vfcore/inference/test_balanced_map.py). Prints the median of
``--reps`` interleaved repetitions; run it with the machine to itself.

    python benchmarks/studies/bench_split.py [--rows 24,48] [--workers 2] [--reps 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402

from vfcore import SimConfig, simulate  # noqa: E402
from vfcore.inference import Prior, Problem, ProblemEvaluator  # noqa: E402
from vfcore.inference.importance import BalancedMap, map_evaluate  # noqa: E402
from vfcore.params import TABLE3  # noqa: E402


def problem() -> Problem:
    """A Table 3 twin in the concealed suites' set-up: coarse mesh, dt 1e-4 s, 0.55 s with 0.25 s
    discarded, E_body, E_cover and p_sub free over Table 2."""
    cfg = SimConfig(mesh="coarse", dt=1e-4)
    y = simulate(TABLE3, cfg).gaw
    prior = Prior({"E_body": (9.0, 15.0), "E_cover": (250.0, 950.0), "p_sub": (400.0, 1800.0)})
    return Problem(y + np.random.default_rng(0).normal(0.0, 0.5, y.size), cfg.fps, prior, sigma_e=1.0, config=cfg)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rows", default="24,48")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--reps", type=int, default=5)
    a = ap.parse_args()
    pb = problem()
    ev = ProblemEvaluator(pb)
    rng = np.random.default_rng(1)
    # a generation near a posterior: rows within 5 % of the prior width about Table 3
    centre = np.array([TABLE3.E_body, TABLE3.E_cover, TABLE3.p_sub])
    width = pb.prior.width
    with ProcessPoolExecutor(a.workers) as pool:
        map_evaluate(ev, np.tile(centre, (a.workers, 1)), map=pool.map, chunk_size=1)  # compile in each
        print(f"{a.workers} workers; ms per generation (median of {a.reps}), same log-likelihoods in every split")
        for n in (int(x) for x in a.rows.split(",")):
            rows = centre + (rng.random((n, 3)) - 0.5) * 0.1 * width
            splits = {
                f"chunks of {-(-40 // a.workers)}": (pool.map, -(-40 // a.workers)),
                f"chunks of {-(-40 // (2 * a.workers))}": (pool.map, -(-40 // (2 * a.workers))),
                "equal parts (BalancedMap)": (BalancedMap(pool.map, a.workers), 40),
            }
            times = {k: [] for k in splits}
            ref = None
            for _ in range(a.reps):
                for k, (m, cs) in splits.items():
                    t = time.perf_counter()
                    out = map_evaluate(ev, rows, map=m, chunk_size=cs)
                    times[k].append(time.perf_counter() - t)
                    if ref is None:
                        ref = out.loglik
                    elif not np.array_equal(out.loglik, ref):
                        raise SystemExit(f"{k}: log-likelihoods differ")
            base = statistics.median(times["equal parts (BalancedMap)"])
            for k, v in times.items():
                med = statistics.median(v)
                print(f"  {n} rows, {k:38s} {med * 1e3:8.0f} ms  ({med / base:.2f}x equal parts)")


if __name__ == "__main__":
    main()
