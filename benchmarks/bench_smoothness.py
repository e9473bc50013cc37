"""Is the six-parameter log-likelihood a smooth function of the parameters? Contact law and time step compared.

Protocol (fixed before the runs that :ref:`inference` reports): the twins of the six-parameter calibration
(``bench_calibration.py``: ``make_twin`` with seeds 1000 + i, all six scaled parameters free on Table 2, x0 at
Table 3, coarse mesh, 0.55 s with 0.25 s discarded, 400 frames at 2 kHz, noise 1 mm^2), each made with the
forward model under test. Through each twin's truth, along a random unit direction of log-ratios (a direction
orthogonal to the common scale, seeded by the twin's index, so the same for every model), the log-likelihood is
evaluated at ``--points`` equally spaced points spanning ``±--span`` in log units (default ±0.02: of the order
of a combination's posterior sd). A smooth likelihood that peaks near the truth rises, then falls: one *turn*
(a sign change of successive differences, differences under 0.5 nat ignored). A staircase or spikes give many.
Printed per twin: turns, largest step between neighbours, range; then per model the twins with at most one
turn and the total turns.

    python benchmarks/bench_smoothness.py --contact projection --dt 1e-4
    python benchmarks/bench_smoothness.py --contact layer --dt 5e-5 --twins 20
    python benchmarks/bench_smoothness.py --flow continuous --contact layer --dt 1e-4
    python benchmarks/bench_smoothness.py --flow continuous --contact layer --span 0.002   # the fine scan
    python benchmarks/bench_smoothness.py --flow continuous --contact layer --likelihood stats

``--likelihood stats`` scores each simulation by the phase-insensitive synthetic likelihood of
:mod:`vfcore.inference.cycle_stats` (the twin's observation against the last 400 frames of the simulated GAW)
instead of the aligned frame-by-frame one.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

TURN_TOL = 0.5  # nats: smaller differences are treated as flat


def turns(loglik: np.ndarray, tol: float = TURN_TOL) -> int:
    """Sign changes of the successive differences of ``loglik`` that exceed ``tol`` in size."""
    d = np.diff(np.asarray(loglik, float))
    s = np.sign(d[np.abs(d) > tol])
    return int(np.sum(s[1:] != s[:-1]))


def log_ratio_direction(seed: int, ndim: int) -> np.ndarray:
    """A random unit vector orthogonal to the all-ones (common-scale) direction."""
    u = np.random.default_rng(seed).normal(size=ndim)
    u -= u.mean()
    return u / np.linalg.norm(u)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--contact", default="projection", help="SimConfig.contact")
    ap.add_argument("--flow", default="paper", help="SimConfig.flow")
    ap.add_argument(
        "--likelihood",
        default="frames",
        choices=("frames", "stats"),
        help="the aligned frame-by-frame likelihood, or the summary-statistics one",
    )
    ap.add_argument("--dt", type=float, default=1e-4)
    ap.add_argument("--rho-inf", type=float, default=1.0, help="SimConfig.rho_inf (1 = the paper's Newmark rule)")
    ap.add_argument("--mesh", default="coarse")
    ap.add_argument("--twins", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--points", type=int, default=41)
    ap.add_argument("--span", type=float, default=0.02)
    a = ap.parse_args(argv)

    from vfcore.config import SimConfig
    from vfcore.inference import Prior, evaluate, make_twin
    from vfcore.params import TABLE3

    cfg = SimConfig(mesh=a.mesh, dt=a.dt, duration=0.55, contact=a.contact, flow=a.flow, rho_inf=a.rho_inf)
    prior = Prior.default(fixed={"x0": TABLE3.as_dict()["x0"]})
    ts = np.linspace(-a.span, a.span, a.points)
    print(
        f"flow={a.flow} contact={a.contact} dt={a.dt:g} rho_inf={a.rho_inf:g} mesh={a.mesh} likelihood={a.likelihood}: {a.points} points over ±{a.span} in log-ratio"
    )
    print("| twin | p_sub (Pa) | turns | largest step (nats) | range (nats) |")
    print("|---|---|---|---|---|")
    counts = []
    for i in range(a.twins):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tw = make_twin(prior, cfg, seed=a.seed + i, sigma_e=1.0, n_obs=400)
            u = log_ratio_direction(i, prior.ndim)
            th = np.exp(np.log(tw.truth)[None, :] + ts[:, None] * u[None, :])
            if a.likelihood == "stats":
                from vfcore.forward import simulate_batch
                from vfcore.inference.cycle_stats import CycleStatsLikelihood

                lik = CycleStatsLikelihood(tw.problem.obs_gaw, cfg.fps, sigma_e=1.0)
                rs = simulate_batch(np.array([prior.to_params(t).as_array() for t in th]), cfg)
                ll = np.array([lik(r.gaw) if r.ok else -np.inf for r in rs])
            else:
                ll = evaluate(th, tw.problem).loglik
        k = turns(ll)
        counts.append(k)
        step = np.max(np.abs(np.diff(ll))) if np.all(np.isfinite(ll)) else np.inf
        rng = np.ptp(ll) if np.all(np.isfinite(ll)) else np.inf
        p_sub = tw.truth[list(prior.names).index("p_sub")]
        print(f"| {i} | {p_sub:.0f} | {k} | {step:.1f} | {rng:.1f} |", flush=True)
    counts = np.array(counts)
    print(
        f"\nflow={a.flow} contact={a.contact} dt={a.dt:g} rho_inf={a.rho_inf:g} mesh={a.mesh} likelihood={a.likelihood}: {int(np.sum(counts <= 1))} of {counts.size} twins smooth "
        f"(at most one turn); {int(counts.sum())} turns in all"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
