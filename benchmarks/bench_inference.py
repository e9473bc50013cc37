"""Twin experiment at a chosen configuration: prior IS (paper, Section 4.2) versus tempered SMC.

Prints the truth, both posteriors (mean +- sd, % of estimate), whether each truth lies within
2 sigma, the SMC-vs-IS agreement (mean difference in IS posterior sigmas, sd ratio), the
simulation counts side by side, diagnostics (ESS, Pareto-k, log-evidence +- MC error) and
wall-clock timings. Writes NetCDF/CSV/figures to --out. Numbers are printed, never asserted.

Full paper configuration (hours of CPU; use many workers):
    python benchmarks/bench_inference.py --mesh medium --dt 5e-5 --draws 50000 --workers 16
Reduced run:
    python benchmarks/bench_inference.py --mesh coarse --dt 1e-4 --draws 5000 --estimate E_body,p_sub,x0
"""

from __future__ import annotations

import argparse
import json
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

from vfcore.config import SimConfig  # noqa: E402
from vfcore.inference import (  # noqa: E402
    DegenerateEnsembleWarning,
    Prior,
    compare,
    flow_contact_table,
    importance_sample,
    make_twin,
    plot_marginals,
    plot_predictive,
    smc,
)
from vfcore.params import PARAM_NAMES, TABLE3  # noqa: E402


def _pool(workers: int):
    if workers <= 1:
        return None
    import multiprocessing as mp

    return mp.get_context("spawn").Pool(workers)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mesh", default="medium")
    ap.add_argument("--duration", type=float, default=0.55, help="simulated time, s (0.25 s discarded)")
    ap.add_argument("--dt", type=float, default=5e-5)
    ap.add_argument("--draws", type=int, default=50_000, help="prior IS draws (paper: 50,000)")
    ap.add_argument("--particles", type=int, default=300, help="SMC particles")
    ap.add_argument(
        "--estimate",
        default=",".join(PARAM_NAMES),
        help="comma-separated parameters to estimate; the rest are fixed at Table 3",
    )
    ap.add_argument("--sigma-e", type=float, default=1.0)
    ap.add_argument("--n-obs", type=int, default=400, help="observed frames at 2000 fps")
    ap.add_argument("--seed", type=int, default=2019)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--chunk", type=int, default=64)
    ap.add_argument("--skip-is", action="store_true")
    ap.add_argument(
        "--truth",
        choices=("prior", "table3"),
        default="prior",
        help="the twin's truth: a draw from the prior, or the paper's Table 3 (its own experiment)",
    )
    ap.add_argument("--out", default="bench_inference_out")
    ap.add_argument(
        "--toy", action="store_true", help="7-parameter linear-Gaussian toy with exact answer instead of the FE model"
    )
    a = ap.parse_args(argv)
    if a.toy:
        return toy_comparison(a)

    est = [n.strip() for n in a.estimate.split(",") if n.strip()]
    fixed = {n: getattr(TABLE3, n) for n in PARAM_NAMES if n not in est}
    prior = Prior.default(fixed=fixed)
    cfg = SimConfig(mesh=a.mesh, dt=a.dt, duration=a.duration)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)

    t0 = time.perf_counter()
    truth = [getattr(TABLE3, n) for n in prior.names] if a.truth == "table3" else None
    twin = make_twin(prior, cfg, seed=a.seed, sigma_e=a.sigma_e, n_obs=a.n_obs, truth=truth)
    t_twin = time.perf_counter() - t0
    problem = twin.problem
    print(f"# twin: config={cfg}\n# estimated={prior.names} fixed={fixed}")
    print(
        f"# truth={twin.truth_dict} (redraws {twin.n_redraws}); n_compare={problem.n_compare}; "
        f"one simulation {t_twin:.2f} s; workers={a.workers}"
    )

    pool = _pool(a.workers)
    mapper = pool.imap if pool is not None else map
    res = {}
    try:
        if not a.skip_is:
            t0 = time.perf_counter()
            with warnings.catch_warnings(record=True) as wlist:
                warnings.simplefilter("always", DegenerateEnsembleWarning)
                post_is = importance_sample(problem, n=a.draws, seed=a.seed, map=mapper, chunk_size=a.chunk)
            res["is"] = (post_is, time.perf_counter() - t0)
            for w in wlist:
                print(f"!! {w.message}")
        t0 = time.perf_counter()
        post_smc = smc(problem, n_particles=a.particles, seed=a.seed, map=mapper, chunk_size=max(1, a.chunk // 4))
        res["smc"] = (post_smc, time.perf_counter() - t0)
    finally:
        if pool is not None:
            pool.close()
            pool.join()

    names = prior.names
    print("\n## Posterior (twin)")
    hdr = f"{'param':<8} {'truth':>10}"
    for k in res:
        hdr += f" | {k + ' mean':>11} {'sd':>9} {'%':>6} {'|z|':>5}"
    print(hdr)
    for j, n in enumerate(names):
        line = f"{n:<8} {twin.truth[j]:10.4g}"
        for p, _ in res.values():
            z = abs(p.mean[j] - twin.truth[j]) / p.sd[j] if p.sd[j] > 0 else float("inf")
            line += f" | {p.mean[j]:11.5g} {p.sd[j]:9.3g} {p.pct[j]:6.2f} {z:5.2f}"
        print(line)
    for k, (p, dt) in res.items():
        inside = np.abs(p.mean - twin.truth) <= 2 * p.sd
        print(
            f"{k}: truth within 2 sd for {int(inside.sum())}/{len(names)} parameters; "
            f"n_simulations={p.n_simulations} n_failed={p.n_failed} wall={dt:.1f} s "
            f"({dt / max(p.n_simulations, 1) * max(a.workers, 1):.3f} s/sim/worker) ESS={p.ess:.1f} "
            f"pareto_k={p.pareto_k:.2f} logZ={p.log_evidence:.2f}+-{p.log_evidence_se:.2f}"
        )
        p.to_netcdf(out / f"posterior_{k}.nc")
        p.to_csv(out / f"posterior_{k}.csv")
        plot_predictive(p, out / f"predictive_{k}.png", title=f"{k}: posterior predictive")
        plot_marginals(p, out / f"marginals_{k}.png", truth=twin.truth_dict)
        print(
            f"{k} flow/contact: "
            + "; ".join(f"{r['quantity']} {r['mean']:.4g}+-{r['sd']:.3g} {r['unit']}" for r in flow_contact_table(p))
        )
    if "is" in res:
        pi, ps = res["is"][0], res["smc"][0]
        print("\n## SMC vs IS agreement (criteria: |dmean| < 0.3 sd_IS, sd ratio within 25%)")
        ok_all = True
        for j, n in enumerate(names):
            dz = (ps.mean[j] - pi.mean[j]) / pi.sd[j]
            r = ps.sd[j] / pi.sd[j]
            ok = abs(dz) < 0.3 and abs(r - 1) < 0.25
            ok_all &= ok
            print(f"{n:<8} dmean/sd_IS={dz:+.3f} sd_SMC/sd_IS={r:.3f} {'ok' if ok else 'DIFFERS'}")
        print(
            f"simulations: IS {pi.n_simulations} vs SMC {ps.n_simulations} "
            f"(ratio {pi.n_simulations / ps.n_simulations:.1f}x); agreement {'met' if ok_all else 'NOT met'}; "
            f"IS ESS {pi.ess:.1f}"
        )
        print("t-tests IS vs SMC (same data; large p expected):")
        for r in compare(pi, ps):
            print(f"  {r['name']:<8} t={r['t']:+.2f} p={r['p']:.3f} std.diff={r['standardized_difference']:+.3f}")
    summary = {
        k: {
            "mean": p.mean.tolist(),
            "sd": p.sd.tolist(),
            "n_simulations": p.n_simulations,
            "wall_s": dt,
            "ess": p.ess,
            "log_evidence": p.log_evidence,
        }
        for k, (p, dt) in res.items()
    }
    summary["truth"] = twin.truth.tolist()
    summary["names"] = list(names)
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return 0


def toy_comparison(a) -> int:
    """IS (a.draws) vs SMC (a.particles) on a 7-D linear-Gaussian problem with a closed form."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "doubles"))  # the test problem
    from linear_gaussian import LinearGaussianToy

    prior = Prior.default()
    toy = LinearGaussianToy(prior, n_obs=12, noise=0.3, seed=0)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pi = importance_sample(toy, prior, n=a.draws, seed=a.seed, chunk_size=10_000)
    ti = time.perf_counter() - t0
    t0 = time.perf_counter()
    ps = smc(toy, prior, n_particles=a.particles, seed=a.seed)
    ts = time.perf_counter() - t0
    print(
        f"# toy: 7-D linear-Gaussian, closed-form posterior (prior-box truncation bound "
        f"{toy.truncation_mass:.3f}); IS {a.draws} draws vs SMC {a.particles} particles"
    )
    print(
        f"{'param':<8} {'exact mean':>11} {'exact sd':>9} | {'IS z':>6} {'IS sd/ex':>8} | {'SMC z':>6} "
        f"{'SMC sd/ex':>9} | {'dmean/sd_IS':>11} {'sd_SMC/sd_IS':>12}"
    )
    for j, n in enumerate(prior.names):
        print(
            f"{n:<8} {toy.mean[j]:11.5g} {toy.sd[j]:9.3g} | {(pi.mean[j] - toy.mean[j]) / toy.sd[j]:+6.2f} "
            f"{pi.sd[j] / toy.sd[j]:8.3f} | {(ps.mean[j] - toy.mean[j]) / toy.sd[j]:+6.2f} {ps.sd[j] / toy.sd[j]:9.3f}"
            f" | {(ps.mean[j] - pi.mean[j]) / pi.sd[j]:+11.3f} {ps.sd[j] / pi.sd[j]:12.3f}"
        )
    print(
        f"log-evidence: exact {toy.log_evidence:.3f}; IS {pi.log_evidence:.3f}+-{pi.log_evidence_se:.3f}; "
        f"SMC {ps.log_evidence:.3f}+-{ps.log_evidence_se:.3f}"
    )
    print(
        f"simulations: IS {pi.n_simulations} (ESS {pi.ess:.1f}, Pareto k {pi.pareto_k:.2f}) vs SMC "
        f"{ps.n_simulations} ({pi.n_simulations / ps.n_simulations:.1f}x fewer, {ps.info['n_generations']} "
        f"generations); wall IS {ti:.2f} s, SMC {ts:.2f} s"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
