"""Delayed-acceptance SMC against plain SMC on six-parameter twins.

Protocol: three twins at random truths inside Table 2 (x0 = 8.4 fixed; rng seeds 1, 2, 3, the first draw
that phonates and closes on the full model), camera noise 1 mm^2; full model: coarse mesh, dt 5e-5 s, 550 ms;
screen: the same on dt 1e-4 s. SMC (log-ratio walk with exact scale moves, the default for six free parameters)
with 200 particles (third argument), seed 0, both runs on the same worker processes.
Reported per twin: full simulations (and screening ones), wall time, the largest change of a posterior mean
in posterior sds and of a posterior sd (relative), and the truth's z-scores under each.
Usage: OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_delayed_acceptance.py [n_twins] [workers] [particles]
"""
from __future__ import annotations

import dataclasses
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from vfcore import SimConfig, simulate  # noqa: E402
from vfcore.inference import TABLE2_BOUNDS, Prior, Problem, smc  # noqa: E402
from vfcore.params import Params  # noqa: E402

NAMES = ("E_body", "E_cover", "E_lig", "p_sub", "rho", "eta")
FULL = SimConfig(mesh="coarse", dt=5e-5)
SCREEN = FULL.replace(dt=1e-4)


def twin(seed: int):
    rng = np.random.default_rng(seed)
    for _ in range(500):
        p = Params(**{n: float(rng.uniform(*TABLE2_BOUNDS[n])) for n in NAMES}, x0=8.4)
        r = simulate(p, FULL)
        if r.ok and r.cycles is not None and r.cycles.period.size > 5 and r.gaw.min() < 0.5 and np.ptp(r.gaw) > 5:
            return p, r.gaw + rng.normal(0.0, 1.0, r.gaw.size), r.fps
    raise RuntimeError("no phonating draw")


def main(n_twins: int, workers: int, particles: int = 200) -> None:
    print(__doc__.split("Usage")[0])
    prior = Prior({n: TABLE2_BOUNDS[n] for n in NAMES}, {"x0": 8.4})
    print("| twin | run | full sims | screening sims | wall (s) | max dmean (sd) | max dsd | truth z (min, max) |")
    print("|---|---|---|---|---|---|---|---|")
    with ProcessPoolExecutor(workers) as ex:
        for k in range(1, n_twins + 1):
            p, y, fps = twin(k)
            full = Problem(obs_gaw=y, fps=fps, prior=prior, sigma_e=1.0, config=FULL)
            cheap = dataclasses.replace(full, config=SCREEN)
            truth = np.array([getattr(p, n) for n in NAMES])
            res = {}
            for label, screen in (("plain", None), ("delayed", cheap)):
                t = time.perf_counter()
                post = smc(full, n_particles=particles, seed=0, map=ex.map, chunk_size=32, screen=screen)
                res[label] = (post, time.perf_counter() - t)
            (a, ta), (b, tb) = res["plain"], res["delayed"]
            dm = np.max(np.abs(b.mean - a.mean) / a.sd)
            ds = np.max(np.abs(b.sd / a.sd - 1.0))
            for label, (post, t) in res.items():
                z = (truth - post.mean) / post.sd
                extra = f"{dm:.2f} | {ds:.2f}" if label == "delayed" else "— | —"
                print(f"| {k} | {label} | {post.n_simulations} | {post.info.get('n_screened', 0)} | {t:.0f} | "
                      f"{extra} | {z.min():+.2f}, {z.max():+.2f} |", flush=True)


if __name__ == "__main__":
    args = sys.argv[1:]
    main(int(args[0]) if args else 3, int(args[1]) if len(args) > 1 else 2, int(args[2]) if len(args) > 2 else 200)
