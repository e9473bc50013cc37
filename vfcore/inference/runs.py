"""Independent SMC runs of one target, pooled into one posterior.

One likelihood-tempered SMC run of a rugged six-parameter likelihood can settle in a basin that holds a
negligible share of the posterior mass, and it cannot tell from inside: its particles agree with each
other. Independent runs (own seeds) find different basins, and a run that missed the dominant one says so
by its evidence, which then lies well below the others' (docs/inference.md, "Independent runs").

The pooling rule, fixed before the calibration that tests it:

* a run whose log evidence is more than ``gap`` nats (default 5) below the best run's is left out: the
  basin it holds carries at most exp(-gap) of the mass of the best run's;
* the runs kept share the posterior equally, each run's own (equal) particle weights scaled by
  1 / runs kept. Weighting them by their evidence instead would lean on estimates whose spread between runs
  in the same basin (several nats) is far above their quoted standard error, and hand one run almost all of
  the weight;
* the evidence is the mean of the runs' Z (each run's estimate is unbiased for Z, so is their mean), with the
  standard error of that mean.

This is the pragmatic remedy of running several chains and discarding the stuck ones; it does not make a
thin run of one basin wider, it only stops one run's luck from deciding which basin is reported.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .evaluation import Evaluation
from .posterior import Posterior

__all__ = ["RUN_GAP", "SEED_STRIDE", "run_seeds", "pool_runs"]

RUN_GAP = 5.0
# a prime stride: run k's seed never meets run 0's seed of a neighbouring twin or job (seed + 1, + 2, ...)
SEED_STRIDE = 7919
_POOL_KEY = 0x9001


def run_seeds(seed: int, runs: int) -> list[int]:
    """The seeds of ``runs`` independent runs; the first is ``seed`` itself, so one run is the plain run."""
    if int(runs) < 1:
        raise ValueError(f"runs must be at least 1, got {runs}")
    return [int(seed) + SEED_STRIDE * k for k in range(int(runs))]


def pool_runs(posts: Sequence[Posterior], *, seed: int = 0, gap: float = RUN_GAP) -> Posterior:
    """Pool finished runs of the same target by the rule of the module docstring.

    ``info["runs"]`` lists every run (seed when known, log evidence, simulations, best particle's
    log-likelihood, kept or not); ``info["runs_kept"]`` counts those pooled."""
    posts = list(posts)
    if not posts:
        raise ValueError("pool_runs needs at least one run")
    if not gap > 0:
        raise ValueError(f"gap must be a positive number of nats, got {gap}")
    names = posts[0].names
    if any(p.names != names for p in posts):
        raise ValueError("runs to pool must estimate the same parameters")
    lz = np.array([p.log_evidence for p in posts], dtype=float)
    if not np.all(np.isfinite(lz)):
        raise ValueError(f"every run needs a finite log evidence to be pooled, got {lz.tolist()}")
    kept = lz >= lz.max() - gap
    share = -math.log(int(kept.sum()))
    samples = np.concatenate([p.samples for p, k in zip(posts, kept) if k])
    logw = np.concatenate([p.log_weights + share for p, k in zip(posts, kept) if k])
    # mean of the runs' Z, and the standard error of that mean, in logs
    z = np.exp(lz - lz.max())
    log_z = float(lz.max() + math.log(z.mean()))
    se = float(z.std(ddof=1) / math.sqrt(z.size) / z.mean()) if z.size > 1 else posts[0].log_evidence_se
    msgs = []
    for p, k in zip(posts, kept):
        msgs += [m for m in p.warnings if k and m not in msgs]
    if not kept.all():
        msgs.append(f"independent runs: {int((~kept).sum())} of {len(posts)} settled more than {gap:g} nats of "
                    f"evidence below the best (log Z {', '.join(f'{v:.1f}' for v in lz)}) and were left out")
    rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(_POOL_KEY,)))
    post = Posterior.from_weighted(names, samples, logw, rng=rng, log_evidence=log_z, log_evidence_se=se,
                                   n_simulations=sum(p.n_simulations for p in posts),
                                   n_failed=sum(p.n_failed for p in posts), method=posts[0].method, check=False,
                                   warnings=msgs, obs_gaw=posts[0].obs_gaw, fps=posts[0].fps)
    post.ess = float(sum(p.ess for p, k in zip(posts, kept) if k))
    post.pareto_k = float("nan")
    pooled = [p for p, k in zip(posts, kept) if k]
    if all(p.predictive is not None and p.predictive_index is not None for p in pooled):
        # predictive row i of a run belongs to its sample predictive_index[i]; shift by the run's offset
        offsets = np.cumsum([0] + [len(p.samples) for p in pooled[:-1]])
        post.predictive = Evaluation.concat([p.predictive for p in pooled])
        post.predictive_index = np.concatenate([p.predictive_index + o for p, o in zip(pooled, offsets)])
    post.area_scale = posts[0].area_scale
    post.model = posts[0].model
    runs = []
    for p, k in zip(posts, kept):
        best = float(np.max(p.predictive.loglik)) if p.predictive is not None else float("nan")
        runs.append({"seed": p.info.get("seed"), "log_evidence": float(p.log_evidence),
                     "log_evidence_se": float(p.log_evidence_se), "n_simulations": int(p.n_simulations),
                     "n_generations": int(p.info.get("n_generations", 0)), "best_loglik": best, "kept": bool(k)})
    post.info.update({"runs": runs, "runs_kept": int(kept.sum()), "run_gap": float(gap),
                      "n_particles": sum(int(p.info.get("n_particles", len(p.samples))) for p in pooled)})
    return post
