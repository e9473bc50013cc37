"""Stopping settled simulations (SimConfig.early_stop): what it saves and what it changes.

Protocol: the 2,000 draws of the shipped coarse reach ensemble (Table 2 priors, seed 20190613,
vfcore/data/reach_1f8e3fcc3b22aa3c.csv: coarse mesh, dt 5e-5 s, 550 ms), simulated in lock-step blocks of
32 with early_stop off and on, one process. Reported: draws stopped, the simulated time they skipped, wall
time of both runs, draws stopped that phonate in the full run (must be 0; phonation as the reach
ensembles measure it, vfcore.inference.reach.draw_measures), the largest GAW difference of a stopped draw
(mm^2), and the largest change of the log-likelihood of any draw against a Table 3 twin recording
(vfcore.inference.problem.score_results, sigma_e = 1 mm^2, the default alignment).
Then the posterior of a fixed twin and seed with early_stop off and on: a Table 3 twin (coarse mesh, the
same config), E_body, E_cover and p_sub free in their Table 2 ranges (the rest at Table 3), SMC with 100
particles and seed 1: simulations, wall time, and the largest change of a posterior mean and sd in units
of the posterior sd.
Usage: OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_early_stop.py [n_draws]
"""

from __future__ import annotations

import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from vfcore import TABLE3, simulate  # noqa: E402
from vfcore.batch import simulate_many  # noqa: E402
from vfcore.data import DATA_DIR  # noqa: E402
from vfcore.inference import TABLE2_BOUNDS, Prior, Problem, smc  # noqa: E402
from vfcore.inference.problem import score_results  # noqa: E402
from vfcore.inference.reach import ReachEnsemble, draw_measures  # noqa: E402


def main(n: int) -> None:
    print(__doc__.split("Usage")[0])
    ens = ReachEnsemble.load(DATA_DIR / "reach_1f8e3fcc3b22aa3c.csv")
    rows = ens.params[:n]
    base = ens.sim_config().replace(fps=2000.0)
    twin = simulate(TABLE3, base)
    problem = Problem(obs_gaw=twin.gaw, fps=twin.fps, prior=ens.prior_obj(), sigma_e=1.0, config=base)
    simulate_many(rows[:2], base, block=2)  # JIT warm-up
    simulate_many(rows[:2], base.replace(early_stop=True), block=2)
    out = {}
    for flag in (False, True):
        t = time.perf_counter()
        res = simulate_many(rows, base.replace(early_stop=flag), block=32)
        out[flag] = (res, time.perf_counter() - t)
    full, t_full = out[False]
    cut, t_cut = out[True]
    stopped = np.array([r.ok and r.settled_at > 0 for r in cut])
    skipped = sum(base.duration - r.settled_at for r, s in zip(cut, stopped) if s)
    phon_full = np.array([draw_measures(r)[0] for r in full])
    phon_cut = np.array([draw_measures(r)[0] for r in cut])
    dg = max((float(np.max(np.abs(a.gaw - b.gaw))) for a, b, s in zip(full, cut, stopped) if s), default=0.0)
    ev_full = score_results(full, problem)
    ev_cut = score_results(cut, problem)
    fin = np.isfinite(ev_full.loglik) & np.isfinite(ev_cut.loglik)
    dll = np.abs(ev_full.loglik[fin] - ev_cut.loglik[fin])
    when = [r.settled_at for r, s in zip(cut, stopped) if s]
    print(f"| draws | {n} |\n|---|---|")
    print(f"| ok (full run) | {sum(r.ok for r in full)} |")
    print(f"| phonate (full run) | {int(phon_full.sum())} |")
    print(f"| stopped early | {int(stopped.sum())} ({stopped.mean():.1%}) |")
    if when:
        print(
            f"| stop time, median (5-95 %) | {np.median(when) * 1e3:.0f} ms "
            f"({np.percentile(when, 5) * 1e3:.0f}-{np.percentile(when, 95) * 1e3:.0f}) |"
        )
    print(f"| simulated time skipped | {skipped / (n * base.duration):.1%} of {n * base.duration:.0f} s |")
    print(f"| wall time, off / on | {t_full:.1f} s / {t_cut:.1f} s ({t_full / t_cut:.2f}x) |")
    print(f"| stopped draws that phonate in the full run | {int((stopped & phon_full).sum())} |")
    print(f"| phonation verdicts changed | {int((phon_full != phon_cut).sum())} |")
    print(f"| largest GAW change of a stopped draw | {dg:.2e} mm^2 |")
    print(
        f"| largest log-likelihood change (twin at Table 3) | {dll.max():.2e} nats "
        f"(over {fin.sum()} draws with finite log-likelihood) |"
    )
    print()
    free = ("E_body", "E_cover", "p_sub")
    prior = Prior({k: TABLE2_BOUNDS[k] for k in free}, {k: v for k, v in TABLE3.as_dict().items() if k not in free})
    post = {}
    for flag in (False, True):
        prob = Problem(obs_gaw=twin.gaw, fps=twin.fps, prior=prior, sigma_e=1.0, config=base.replace(early_stop=flag))
        t = time.perf_counter()
        p = smc(prob, n_particles=100, seed=1)
        post[flag] = (p, time.perf_counter() - t)
    (a, ta), (b, tb) = post[False], post[True]
    sa, sb = a.samples, b.samples
    dm = np.max(np.abs(sb.mean(axis=0) - sa.mean(axis=0)) / sa.std(axis=0))
    ds = np.max(np.abs(sb.std(axis=0) / sa.std(axis=0) - 1.0))
    print("| twin SMC (3 free, 100 particles, seed 1) | off | on |\n|---|---|---|")
    print(f"| simulations | {a.n_simulations} | {b.n_simulations} |")
    print(f"| wall time | {ta:.1f} s | {tb:.1f} s |")
    print(f"| posterior means | {np.round(sa.mean(axis=0), 3).tolist()} | {np.round(sb.mean(axis=0), 3).tolist()} |")
    print(f"| largest change of a mean / an sd | {dm:.2e} sd / {ds:.2e} |")
    print(f"| identical samples | {np.array_equal(sa, sb)} |")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 2000)
