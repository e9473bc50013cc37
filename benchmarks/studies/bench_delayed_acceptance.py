"""Delayed-acceptance SMC against plain SMC on six-parameter twins.

Protocol: ``--twins`` twins at random truths inside Table 2 (x0 = 8.4 fixed; rng seeds 1, 2, 3, ..., the first
draw that phonates and closes on the full model), camera noise 1 mm^2; full model: coarse mesh, dt 5e-5 s,
550 ms, contact law ``--contact``; screen: the same on dt ``--screen-dt``. SMC (log-ratio walk with exact
scale moves, the default for six free parameters) with ``--particles`` particles; per twin three runs on the
same worker processes: plain SMC with seed 0, delayed acceptance with seed 0, and plain SMC with seed 1 (the
Monte Carlo spread a change of sampler must be judged against).
Reported per twin and run: full simulations (and screening ones), wall time, and on the five scale-invariant
combinations a GAW determines (``vfcore.inference.identify``): the largest change of a posterior mean against
plain seed 0 in its posterior sds and of a posterior sd (relative), and the truth's largest |z|.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/studies/bench_delayed_acceptance.py --twins 3 --workers 2 --particles 100
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402

from vfcore import SimConfig, simulate  # noqa: E402
from vfcore.inference import TABLE2_BOUNDS, Prior, Problem, smc  # noqa: E402
from vfcore.inference.identify import scale_invariant_combinations  # noqa: E402
from vfcore.params import Params  # noqa: E402

NAMES = ("E_body", "E_cover", "E_lig", "p_sub", "rho", "eta")


def twin(seed: int, config: SimConfig):
    rng = np.random.default_rng(seed)
    for _ in range(500):
        p = Params(**{n: float(rng.uniform(*TABLE2_BOUNDS[n])) for n in NAMES}, x0=8.4)
        r = simulate(p, config)
        if r.ok and r.cycles is not None and r.cycles.period.size > 5 and r.gaw.min() < 0.5 and np.ptp(r.gaw) > 5:
            return p, r.gaw + rng.normal(0.0, 1.0, r.gaw.size), r.fps
    raise RuntimeError("no phonating draw")


def combination_stats(post, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Posterior mean and sd of each scale-invariant combination ``weights @ log theta``."""
    lc = np.log(post.samples) @ weights.T
    return lc.mean(axis=0), lc.std(axis=0)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--twins", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--particles", type=int, default=100)
    ap.add_argument("--contact", default="projection", help="SimConfig.contact of the full and the screening model")
    ap.add_argument("--screen-dt", type=float, default=1e-4)
    a = ap.parse_args(argv)
    full_cfg = SimConfig(mesh="coarse", dt=5e-5, contact=a.contact)
    screen_cfg = full_cfg.replace(dt=a.screen_dt)
    prior = Prior({n: TABLE2_BOUNDS[n] for n in NAMES}, {"x0": 8.4})
    combos = scale_invariant_combinations(prior.names)
    w = np.array([[c.get(n, 0.0) for n in prior.names] for c in combos])
    print(f"contact={a.contact}, screen dt={a.screen_dt:g} s, {a.particles} particles, {a.workers} workers")
    print("| twin | run | full sims | screening sims | wall (s) | max dmean (sd) | max dsd | truth max abs z |")
    print("|---|---|---|---|---|---|---|---|")
    with ProcessPoolExecutor(a.workers) as ex:
        for k in range(1, a.twins + 1):
            p, y, fps = twin(k, full_cfg)
            full = Problem(obs_gaw=y, fps=fps, prior=prior, sigma_e=1.0, config=full_cfg)
            cheap = dataclasses.replace(full, config=screen_cfg)
            c_true = w @ np.log(np.array([getattr(p, n) for n in NAMES]))
            res = {}
            for label, screen, seed in (("plain", None, 0), ("delayed", cheap, 0), ("plain, seed 1", None, 1)):
                t = time.perf_counter()
                post = smc(full, n_particles=a.particles, seed=seed, map=ex.map, chunk_size=16, screen=screen)
                res[label] = (post, time.perf_counter() - t)
            m0, s0 = combination_stats(res["plain"][0], w)
            for label, (post, t) in res.items():
                m, s = combination_stats(post, w)
                z = np.max(np.abs((m - c_true) / s))
                extra = (
                    "— | —"
                    if label == "plain"
                    else f"{np.max(np.abs(m - m0) / s0):.2f} | {np.max(np.abs(s / s0 - 1.0)):.2f}"
                )
                print(
                    f"| {k} | {label} | {post.n_simulations} | {post.info.get('n_screened', 0)} | {t:.0f} | "
                    f"{extra} | {z:.2f} |",
                    flush=True,
                )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
