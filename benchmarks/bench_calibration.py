"""Calibration of the credible intervals over many twin data sets.

For each of --datasets twins (truth drawn from the prior, model data + N(0, sigma_e^2) noise),
run the sampler (SMC by default, or prior IS) and record whether each estimated parameter's
central 90% credible interval covers the truth. A calibrated posterior covers ~90%; the
acceptance band for this project is 80-97% over >= 20 data sets. Prints per-parameter and
pooled coverage with a Clopper-Pearson 95% interval, the simulation counts and timings.

Where two or more of the six scaled parameters are estimated, the coverage of each scale-invariant
combination a GAW determines (``vfcore.inference.identify.scale_invariant_combinations``; its interval
from the posterior draws of ``sum a_i log theta_i``) is printed too: with all six free the absolute
values are set by the prior's box along the common scale, so these are the numbers the data stand
behind, and the pooled verdict is then the combinations' (the parameters' pooled line carries none).
Each twin's fit also gets the regularity check a job runs (``vfcore.diagnose.regularity``, at the posterior mean;
docs/inference.md, "Irregular vibration" and "Aperiodic vibration"), and the combinations' coverage is printed again
for the fits it calls smooth and those it flags (irregular or rough): a split by what the tool tells its user, never
by the truth. ``--resume`` adds the check to the rows
of an earlier run that lack it.
``--symmetry off`` runs the plain random walk instead of the log-ratio walk with exact scale moves
(``vfcore.inference.symmetry``), for comparison.

    python benchmarks/bench_calibration.py --datasets 20 --mesh coarse --dt 1e-4 --workers 16
    python benchmarks/bench_calibration.py --datasets 20 --estimate E_body,E_cover,E_lig,p_sub,rho,eta \
        --particles 100 --workers 2          # six free: the common scale from the prior
    python benchmarks/bench_calibration.py --datasets 20 --estimate E_body,E_cover,E_lig,p_sub,rho,eta \
        --particles 100 --workers 2 --dt 5e-5 --contact layer    # the model whose likelihood is smooth
    python benchmarks/bench_calibration.py --datasets 20 --estimate E_body,E_cover,E_lig,p_sub,rho,eta \
        --particles 100 --workers 2 --dt 5e-5 --contact layer --runs 3 --out DIR    # 3 runs pooled a twin
    ... --resume --out DIR           # after an interruption: keeps DIR's finished twins, runs the others
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import warnings
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

from vfcore.config import SimConfig  # noqa: E402
from vfcore.inference import Prior, importance_sample, make_twin, smc  # noqa: E402
from vfcore.inference.identify import SCALED, combination_label, scale_invariant_combinations  # noqa: E402
from vfcore.inference.runs import RUN_RULES, pool_runs, run_seeds  # noqa: E402
from vfcore.params import PARAM_NAMES, TABLE3  # noqa: E402

#: held values of the parameters not estimated with ``--prior-set human`` (inside its box; :ref:`inference`)
HUMAN_HELD = {"E_body": 100.0, "E_cover": 5000.0, "E_lig": 15.0, "p_sub": 1500.0, "rho": 1050.0, "eta": 3.0, "x0": 8.4}


#: The acceptance band of pooled 90 % coverage (module docstring).
BAND = (0.80, 0.97)


def clopper_pearson(k: int, n: int, alpha: float = 0.05) -> tuple[float, float]:
    lo = stats.beta.ppf(alpha / 2, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(1 - alpha / 2, k + 1, n - k) if k < n else 1.0
    return float(lo), float(hi)


def regularity_flag(problem, theta, seed: int) -> dict:
    """The regularity check a job runs on its fit (``vfcore.diagnose.regularity.sensitivity``: 7 simulations), here
    at the posterior mean: ``irregular`` where a relative 1e-6 move changes the log-likelihood by more than 1 nat,
    ``rough`` where a relative 1e-4 move's second difference exceeds 3 nats or the waveform does not repeat within
    4 cycles; ``smooth`` is neither. A check that cannot run sets both flags (the tool then vouches for nothing)."""
    from vfcore.diagnose.regularity import sensitivity

    try:
        s = sensitivity(problem, theta, seed=seed)
    except RuntimeError:
        return {
            "irregular": True,
            "rough": True,
            "smooth": False,
            "regularity_max_change": None,
            "max_second_difference": None,
            "aperiodicity": None,
        }
    return {
        "irregular": s.irregular,
        "rough": s.rough,
        "smooth": s.smooth,
        "regularity_max_change": s.max_change,
        "max_second_difference": s.max_second_difference,
        "aperiodicity": s.aperiodicity,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--datasets", type=int, default=20)
    ap.add_argument("--mesh", default="coarse")
    ap.add_argument("--duration", type=float, default=0.55, help="simulated time, s (0.25 s discarded)")
    ap.add_argument("--dt", type=float, default=1e-4)
    ap.add_argument("--estimate", default=",".join(PARAM_NAMES))
    ap.add_argument("--sampler", choices=("smc", "is"), default="smc")
    ap.add_argument("--particles", type=int, default=300)
    ap.add_argument("--draws", type=int, default=20_000)
    ap.add_argument("--sigma-e", type=float, default=1.0)
    ap.add_argument("--n-obs", type=int, default=400)
    ap.add_argument("--level", type=float, default=0.9)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--chunk", type=int, default=16)
    ap.add_argument(
        "--prior-set",
        choices=("paper", "human"),
        default="paper",
        help="default bounds: the paper's Table 2 or the human set (docs/inference.md, 'Prior sets')",
    )
    ap.add_argument(
        "--symmetry",
        choices=("auto", "off"),
        default="auto",
        help="auto: log-ratio walk and exact scale moves when all six scaled parameters are free",
    )
    ap.add_argument("--contact", default="projection", help="midline contact law (SimConfig.contact)")
    ap.add_argument(
        "--max-moves",
        type=int,
        default=None,
        help="SMC: most Metropolis moves per generation (the sampler's default when omitted)",
    )
    ap.add_argument(
        "--runs",
        type=int,
        default=1,
        help="SMC: independent runs per twin, pooled (vfcore.inference.runs) by --run-rule; the "
        "combinations covered under every rule are recorded too",
    )
    ap.add_argument(
        "--run-rule",
        choices=tuple(RUN_RULES),
        default="loglik",
        help="which runs are pooled (vfcore.inference.runs.RUN_RULES)",
    )
    ap.add_argument(
        "--resume",
        action="store_true",
        help="keep the twins of --out's calibration_partial.json and run only the others",
    )
    ap.add_argument("--init-factor", type=int, default=1, help="SMC: first population = factor x particles")
    ap.add_argument(
        "--ids", default=None, help="comma-separated twin indices to run (0-based; twin i uses seed --seed + i)"
    )
    ap.add_argument("--out", default="bench_calibration_out")
    a = ap.parse_args(argv)

    est = [n.strip() for n in a.estimate.split(",") if n.strip()]
    # what is not estimated: Table 3, or for the human set values inside its box (x0 at its phonating end)
    values = TABLE3.as_dict() if a.prior_set == "paper" else HUMAN_HELD
    held = {n: values[n] for n in PARAM_NAMES if n not in est}
    prior = Prior.default(fixed=held, prior_set=a.prior_set)
    cfg = SimConfig(mesh=a.mesh, dt=a.dt, duration=a.duration, contact=a.contact)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    pool = None
    if a.workers > 1:
        import multiprocessing as mp

        pool = mp.get_context("spawn").Pool(a.workers)
    mapper = pool.imap if pool is not None else map
    combos = scale_invariant_combinations(prior.names)
    # every scaled parameter free: nothing but the prior's box places the fit along the common scale
    scale_free = set(SCALED) <= set(prior.names)
    combo_names = [combination_label(c) for c in combos]
    combo_w = np.array([[c.get(n, 0.0) for n in prior.names] for c in combos]).reshape(len(combos), prior.ndim)
    rows = []
    partial = out / "calibration_partial.json"
    if a.resume and partial.exists():
        rows = json.loads(partial.read_text())["rows"]
    t_all = time.perf_counter()
    try:
        ids = [int(t) for t in a.ids.split(",")] if a.ids else range(a.datasets)
        for r in rows:
            if "rough" not in r:  # a row of an earlier version of this benchmark: add the product's check
                r.update(
                    regularity_flag(
                        make_twin(prior, cfg, seed=a.seed + r["dataset"], sigma_e=a.sigma_e, n_obs=a.n_obs).problem,
                        np.array(r["mean"]),
                        a.seed + r["dataset"],
                    )
                )
        for i in ids:
            if any(r["dataset"] == i for r in rows):
                continue
            tw = make_twin(prior, cfg, seed=a.seed + i, sigma_e=a.sigma_e, n_obs=a.n_obs)
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                if a.sampler == "smc":
                    # the runs one by one, so that every pooling rule can be scored on the same runs
                    runs = [
                        smc(
                            tw.problem,
                            n_particles=a.particles,
                            seed=s,
                            map=mapper,
                            chunk_size=a.chunk,
                            symmetry="auto" if a.symmetry == "auto" else None,
                            init_factor=a.init_factor,
                            **({"max_moves": a.max_moves} if a.max_moves else {}),
                        )
                        for s in run_seeds(a.seed + i, a.runs)
                    ]
                    pooled = {r: pool_runs(runs, seed=a.seed + i, rule=r) for r in RUN_RULES} if a.runs > 1 else {}
                    post = pooled[a.run_rule] if pooled else runs[0]
                else:
                    pooled = {}
                    post = importance_sample(tw.problem, n=a.draws, seed=a.seed + i, map=mapper, chunk_size=a.chunk * 4)
            wall = time.perf_counter() - t0
            # did the sampler find the truth's basin? (a twin's truth scores near the mode; a posterior far
            # below it is a mode-finding failure, not an honest posterior)
            from vfcore.inference import evaluate

            ll_truth = float(evaluate(tw.truth[None, :], tw.problem).loglik[0])
            pred = getattr(post, "predictive", None)
            ll_best = float(np.max(pred.loglik)) if pred is not None else float("nan")
            lo, hi = post.credible_interval(a.level)
            cover = (lo <= tw.truth) & (tw.truth <= hi)
            z = (post.mean - tw.truth) / post.sd
            q = (1.0 - a.level) / 2.0
            c_true = combo_w @ np.log(tw.truth)

            def combo_cover(p):
                # the pooled runs are equally weighted particles of equal-sized runs: plain quantiles
                lc = np.log(p.samples) @ combo_w.T  # (n_draws, n_combos)
                lo_, hi_ = np.quantile(lc, q, axis=0), np.quantile(lc, 1.0 - q, axis=0)
                return (lo_ <= c_true) & (c_true <= hi_), (lc.mean(axis=0) - c_true) / lc.std(axis=0)

            c_cover, c_z = combo_cover(post)
            by_rule = {r: combo_cover(p)[0].tolist() for r, p in pooled.items()}
            per_run = [combo_cover(p)[0].tolist() for p in runs] if pooled else []
            rows.append(
                {
                    "dataset": i,
                    "truth": tw.truth.tolist(),
                    "mean": post.mean.tolist(),
                    "sd": post.sd.tolist(),
                    "covered": cover.tolist(),
                    "z": z.tolist(),
                    "combo_covered": c_cover.tolist(),
                    "combo_z": c_z.tolist(),
                    "n_simulations": post.n_simulations,
                    "n_failed": post.n_failed,
                    "loglik_truth": ll_truth,
                    "loglik_best": ll_best,
                    "ess": post.ess,
                    "wall_s": wall,
                    "warnings": post.warnings,
                    "runs": post.info.get("runs"),
                    "combo_covered_by_rule": by_rule,
                    "combo_covered_per_run": per_run,
                    **regularity_flag(tw.problem, post.mean, a.seed + i),
                }
            )
            print(
                f"[{i:2d}] covered {int(cover.sum())}/{cover.size}  |z|max={np.max(np.abs(z)):.2f}  "
                f"sims={post.n_simulations} failed={post.n_failed} ESS={post.ess:.0f} {wall:.1f} s  "
                f"loglik truth {ll_truth:.1f} best {ll_best:.1f}"
                + (f"  combinations {int(c_cover.sum())}/{c_cover.size}" if combos else ""),
                flush=True,
            )
            # the rows so far, so an interrupted run keeps what it measured
            partial.write_text(json.dumps({"names": list(prior.names), "combinations": combo_names, "rows": rows}))
    finally:
        if pool is not None:
            pool.close()
            pool.join()
    cov = np.array([r["covered"] for r in rows])
    zs = np.array([r["z"] for r in rows])
    print(
        f"\n## {int(100 * a.level)}% credible-interval coverage over {len(rows)} twin data sets "
        f"({a.sampler}, mesh={a.mesh}, dt={a.dt:g}, sigma_e={a.sigma_e})"
    )
    print(f"{'param':<8} {'covered':>8} {'rate':>6} {'95% CI':>15} {'mean z':>7} {'sd z':>6}")
    for j, n in enumerate(prior.names):
        k = int(cov[:, j].sum())
        lo, hi = clopper_pearson(k, cov.shape[0])
        print(
            f"{n:<8} {k:>4}/{cov.shape[0]:<3} {k / cov.shape[0]:6.2f} [{lo:.2f}, {hi:.2f}]  "
            f"{zs[:, j].mean():+7.2f} {zs[:, j].std(ddof=1):6.2f}"
        )
    if combos:
        ccov = np.array([r["combo_covered"] for r in rows])
        czs = np.array([r["combo_z"] for r in rows])
        print("scale-invariant combinations (what a GAW determines):")
        for j, name in enumerate(combo_names):
            k = int(ccov[:, j].sum())
            lo, hi = clopper_pearson(k, ccov.shape[0])
            # median |z|: a collapsed run has a zero spread and an unbounded z
            print(
                f"{name:<20} {k:>4}/{ccov.shape[0]:<3} {k / ccov.shape[0]:6.2f} [{lo:.2f}, {hi:.2f}]  "
                f"median |z| {np.median(np.abs(czs[:, j])):.2f}"
            )
        # split by what the fit itself says, never by the truth: the job's regularity check, and with several runs
        # whether they agree (no run left out by the pooling rule: runs that settle on different best
        # log-likelihoods show that the sampler missed a basin at least once)
        flag = np.array([not r["smooth"] for r in rows])  # every row has it: --resume adds it first
        splits = [("fits checked smooth", ~flag), ("fits flagged rough", flag)]
        if any(r.get("runs") for r in rows):
            agree = np.array([bool(r.get("runs")) and all(x["kept"] for x in r["runs"]) for r in rows])
            splits += [
                ("runs agree", agree),
                ("runs disagree", ~agree),
                ("smooth, runs agree", agree & ~flag),
                ("rough or disagree", ~(agree & ~flag)),
            ]
        for label, sel in splits:
            k, n = int(ccov[sel].sum()), int(ccov[sel].size)
            lo, hi = clopper_pearson(k, n) if n else (math.nan, math.nan)
            print(
                f"{label:<24} {int(sel.sum()):>2} twins: combinations {k}/{n}"
                + (f" {k / n:.2f} [{lo:.2f}, {hi:.2f}]" if n else "")
            )
    pooled_cov = {"parameters": (int(cov.sum()), cov.size)}
    if combos:
        pooled_cov["combinations"] = (int(ccov.sum()), ccov.size)
    # with all six scaled parameters free a parameter's interval is the prior box's length of the common-scale
    # ray: its coverage says little about the data, so the verdict is then the combinations'
    judged = "combinations" if scale_free else "parameters"
    for what, (k, n) in pooled_cov.items():
        lo, hi = clopper_pearson(k, n)
        if what == judged:
            verdict = "within" if BAND[0] <= k / n <= BAND[1] else "OUTSIDE"
            tail = f"-> {verdict} the {100 * BAND[0]:.0f}-{100 * BAND[1]:.0f}% band"
        else:
            tail = "(no verdict: the common scale is the prior's)" if what == "parameters" else ""
        print(f"pooled {what:<12} {k:>4}/{n:<3} {k / n:6.2f} [{lo:.2f}, {hi:.2f}]  {tail}")
    gap = np.array([r["loglik_truth"] - r["loglik_best"] for r in rows])
    print(
        f"truth above the best particle by > 10 nats (the sampler missed the truth's basin): "
        f"{int(np.sum(gap > 10))} of {len(rows)}"
    )
    sims = [r["n_simulations"] for r in rows]
    print(
        f"simulations per data set: mean {np.mean(sims):.0f} (min {min(sims)}, max {max(sims)}); "
        f"total wall {time.perf_counter() - t_all:.0f} s with {a.workers} workers"
    )
    (out / "calibration.json").write_text(
        json.dumps(
            {
                "names": list(prior.names),
                "combinations": combo_names,
                "rows": rows,
                **{f"pooled_{w}_coverage": k / n for w, (k, n) in pooled_cov.items()},
            },
            indent=1,
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
