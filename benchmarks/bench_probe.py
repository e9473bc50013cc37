"""How well the short timed probe predicts a whole simulation's cost (the expected cost `vfinfer infer` and
`vfinfer diagnose` print before a run).

Protocol: for each model (the diagnosis suites' coarse mesh at dt 1e-4 s and the inference default, medium
mesh at dt 5e-5 s; 0.55 s simulated), draw ``--rows`` points from the Table 2 prior (seed 0), time the
probe (:func:`vfcore.batch.probe_seconds_per_sim`: one run of the rows for a short model time, scaled
by the duration) with each row count and length asked and with the probe's former 8 rows and 0.05 s, and the
same rows simulated whole in lock-step blocks of 32 with early stopping, as a fit runs them; ``--reps``
rounds, the whole run and the probes interleaved in each. Prints the medians and the ratio probe / whole
(median and range over the rounds). One thread, one core; on a virtual machine the time per simulation
drifts by up to 1.8x between minutes, which the interleaving keeps out of the ratio.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/bench_probe.py
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vfcore.batch import probe_seconds_per_sim, simulate_many  # noqa: E402
from vfcore.config import SimConfig  # noqa: E402
from vfcore.inference import Prior  # noqa: E402
from vfcore.inference.importance import draw_prior  # noqa: E402

MODELS = {
    "coarse, dt 1e-4 s": SimConfig(mesh="coarse", dt=1e-4, duration=0.55, discard=0.25, fps=2000.0),
    "medium, dt 5e-5 s": SimConfig(mesh="medium", dt=5e-5, duration=0.55, discard=0.25, fps=4000.0),
}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rows", type=int, default=64, help="prior draws simulated whole")
    ap.add_argument("--probes", default="8:0.1,32:0.1,32:0.2", help="probe row counts and lengths (s), ROWS:S,...")
    ap.add_argument("--reps", type=int, default=5)
    a = ap.parse_args(argv)
    probes = [(int(p.split(":")[0]), float(p.split(":")[1])) for p in a.probes.split(",")]
    prior = Prior.default()
    rows = prior.full_array(draw_prior(prior, a.rows, 0))
    print(f"{'model':<20} {'probe':<16} {'probe ms':>9} {'whole ms':>9} {'ratio (median, range)':>24}")
    for name, cfg in MODELS.items():
        simulate_many(rows[:1], cfg.replace(duration=cfg.dt * 4, discard=0.0), block=1)
        whole, probed = [], {p: [] for p in ["old", *probes]}
        for _ in range(a.reps):  # interleaved: the machine's drift falls on both alike
            t = time.perf_counter()
            simulate_many(rows, cfg, block=32)
            whole.append((time.perf_counter() - t) / len(rows))
            for n, s in probes:
                probed[(n, s)].append(probe_seconds_per_sim(rows[:n], cfg, s))
            probed["old"].append(probe_seconds_per_sim(rows[:8], cfg, 0.05))
        for key, ps in probed.items():
            r = np.array(ps) / np.array(whole)
            label = "8 rows, 0.05 s" if key == "old" else f"{key[0]} rows, {key[1]:g} s"
            print(
                f"{name:<20} {label:<16} {np.median(ps) * 1e3:9.1f} {np.median(whole) * 1e3:9.1f} "
                f"{np.median(r):10.2f} ({r.min():.2f}-{r.max():.2f})"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
