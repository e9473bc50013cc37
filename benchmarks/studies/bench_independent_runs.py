"""Independent SMC runs of one six-parameter twin: do they find different basins, and does pooling them cover?

Protocol: the twins of the six-parameter calibration (``bench_calibration.py``: ``make_twin`` with seed 1000 + i,
all six scaled parameters free on Table 2, x0 at Table 3, coarse mesh, the compliant contact layer, dt 5e-5 s,
0.55 s with 0.25 s discarded, 400 frames at 2 kHz, noise 1 mm^2). Per twin, ``--runs`` SMC runs of ``--particles``
particles with seeds 1000 + i + 7919 k (k = 0 is the calibration's own run). Per run: the evidence, the best
final particle's log-likelihood (against the truth's: a run whose best particle lies far below the truth missed
its basin), and the z-scores and 90 % coverage of the six scale-invariant combinations. Then three poolings of
the runs' final particles, each run's particles sharing its weight equally:

* ``evidence``: run weights proportional to exp(log Z_k) (right when each run holds one whole basin; it leans
  on the evidence estimates, whose spread between runs in the same basin is several nats, not their quoted se);
* ``equal``: every run the same weight (wrong basins included at full weight);
* ``kept``: equal weights over the runs whose log Z is within ``--gap`` nats of the best run's, the others
  dropped (a basin ``gap`` nats below holds exp(-gap) of the mass).

    python benchmarks/studies/bench_independent_runs.py --ids 0,5,13 --runs 4 --workers 2      # ~30 min on 2 cores
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402

from vfcore.inference.runs import SEED_STRIDE  # noqa: E402

SIX = ("E_body", "E_cover", "E_lig", "p_sub", "rho", "eta")


def weighted_interval(x: np.ndarray, w: np.ndarray, level: float = 0.9) -> tuple[float, float]:
    """Central ``level`` interval of the weighted draws ``x`` (weights summing to 1)."""
    o = np.argsort(x)
    cs = np.cumsum(w[o])
    q = (1.0 - level) / 2.0
    lo = x[o][min(np.searchsorted(cs, q), x.size - 1)]
    hi = x[o][min(np.searchsorted(cs, 1.0 - q), x.size - 1)]
    return float(lo), float(hi)


def pooled_coverage(draws: list[np.ndarray], run_w: np.ndarray, truth: np.ndarray) -> int:
    """Combinations (columns of each run's ``draws``) whose pooled 90 % interval covers ``truth``."""
    x = np.concatenate(draws)
    w = np.concatenate([np.full(len(d), wk / len(d)) for d, wk in zip(draws, run_w)])
    return sum(
        int(lo <= t <= hi) for lo, hi, t in (weighted_interval(x[:, j], w) + (truth[j],) for j in range(truth.size))
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ids", default="0,5,13")
    ap.add_argument("--runs", type=int, default=4)
    ap.add_argument("--particles", type=int, default=100)
    ap.add_argument("--gap", type=float, default=5.0, help="'kept' pooling: nats below the best run's log Z")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)

    from vfcore.config import SimConfig
    from vfcore.inference import Prior, evaluate, make_twin, smc
    from vfcore.inference.identify import scale_invariant_combinations
    from vfcore.params import PARAM_NAMES, TABLE3

    prior = Prior.default(fixed={n: TABLE3.as_dict()[n] for n in PARAM_NAMES if n not in SIX})
    cfg = SimConfig(mesh="coarse", dt=5e-5, duration=0.55, contact="layer")
    W = np.array([[c.get(n, 0.0) for n in prior.names] for c in scale_invariant_combinations(prior.names)])
    pool = None
    if a.workers > 1:
        import multiprocessing as mp

        pool = mp.get_context("spawn").Pool(a.workers)
    mapper = pool.imap if pool is not None else map
    print("| twin | run | log Z | best loglik (truth) | combinations covered | combination z | sims | wall (s) |")
    print("|---|---|---|---|---|---|---|---|")
    summary = []
    try:
        for i in (int(t) for t in a.ids.split(",")):
            tw = make_twin(prior, cfg, seed=1000 + i, sigma_e=1.0, n_obs=400)
            truth = W @ np.log(tw.truth)
            ll_truth = float(evaluate(tw.truth[None, :], tw.problem).loglik[0])
            lz, draws = [], []
            for k in range(a.runs):
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    post = smc(
                        tw.problem, n_particles=a.particles, seed=1000 + i + SEED_STRIDE * k, map=mapper, chunk_size=32
                    )
                lc = np.log(post.samples) @ W.T
                z = (lc.mean(0) - truth) / lc.std(0)
                cov = pooled_coverage([lc], np.ones(1), truth)
                lz.append(post.log_evidence)
                draws.append(lc)
                print(
                    f"| {i} | {k} | {post.log_evidence:.1f} | {np.max(post.predictive.loglik):.1f} ({ll_truth:.1f}) | "
                    f"{cov}/6 | {', '.join(f'{v:.1f}' for v in z)} | {post.n_simulations} | "
                    f"{time.perf_counter() - t0:.0f} |",
                    flush=True,
                )
            lz = np.array(lz)
            ev = np.exp(lz - lz.max())
            kept = (lz >= lz.max() - a.gap).astype(float)
            row = {
                name: pooled_coverage(draws, w / w.sum(), truth)
                for name, w in (("evidence", ev), ("equal", np.ones(a.runs)), ("kept", kept))
            }
            row["first run"] = pooled_coverage(draws[:1], np.ones(1), truth)
            summary.append((i, row, int(kept.sum())))
    finally:
        if pool is not None:
            pool.close()
            pool.join()
    print(
        f"\n| twin | first run alone | pooled by evidence | pooled equally | kept (within {a.gap:g} nats), runs kept |"
    )
    print("|---|---|---|---|---|")
    for i, row, nk in summary:
        print(f"| {i} | {row['first run']}/6 | {row['evidence']}/6 | {row['equal']}/6 | {row['kept']}/6, {nk} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
