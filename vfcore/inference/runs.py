"""Independent SMC runs of one target, pooled into one posterior.

One likelihood-tempered SMC run of a rugged six-parameter likelihood can settle in a basin that holds a
negligible share of the posterior mass, and it cannot tell from inside: its particles agree with each
other. Independent runs (own seeds) find different basins, and a run that missed the best one says so by
the best log-likelihood its final particles reach, which then lies well below the others'
(:ref:`inference-samplers-independent-runs`).

Which runs are pooled (``rule``):

* ``"loglik"`` (default): a run whose best final particle's log-likelihood is more than ``gap`` nats
  (default 3) below the best run's is left out. Runs kept so agreed on it to within 1.4 nats (2.4 where no
  run found the truth's basin), and the others fell 4.4 to 1,458 nats short (20 six-parameter twins, 3 runs each;
  :ref:`inference`);
* ``"evidence"``: a run whose log evidence is more than ``gap`` nats (default 5) below the best run's is left
  out (the basin it holds would carry at most exp(-gap) of the mass). On the same twins the SMC evidence of
  runs whose best particles agree spread by up to 143 nats (against quoted errors of 0.3-0.5), so this rule
  drops runs of the right basin by luck and keeps the luckiest.

The runs kept share the posterior equally, each run's own (equal) particle weights scaled by 1 / runs kept:
weighting them by their evidence would lean on the same unreliable estimates. The evidence is the mean of
the runs' Z (each run's estimate is unbiased for Z, so is their mean), with the standard error of that mean.

Runs that disagree are a warning as well as a filter: on two fresh sets of six-parameter twins, fits whose runs
disagreed covered 48 of 108 combinations with their 90 % intervals, fits whose runs agreed and whose likelihood was
smooth 57 of 66 (:ref:`validation-inference-calibration-do-the-runs-agree`).

This is the pragmatic remedy of running several chains and discarding the stuck ones; it does not make a
thin run of one basin wider, it only stops one run's luck from deciding which basin is reported.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .evaluation import Evaluation
from .posterior import Posterior

__all__ = ["RUN_RULES", "RUN_GAP", "SEED_STRIDE", "best_loglik", "run_seeds", "pool_runs"]

#: the pooling rules and their default gaps, nats (module docstring)
RUN_RULES = {"loglik": 3.0, "evidence": 5.0}
RUN_GAP = RUN_RULES["loglik"]
# a prime stride: run k's seed never meets run 0's seed of a neighbouring twin or job (seed + 1, + 2, ...)
SEED_STRIDE = 7919
_POOL_KEY = 0x9001


def run_seeds(seed: int, runs: int) -> list[int]:
    """The seeds of ``runs`` independent runs; the first is ``seed`` itself, so one run is the plain run."""
    if int(runs) < 1:
        raise ValueError(f"runs must be at least 1, got {runs}")
    return [int(seed) + SEED_STRIDE * k for k in range(int(runs))]


def best_loglik(post: Posterior) -> float:
    """The largest log-likelihood among a run's final particles (``info["max_loglik"]``, else its predictions);
    NaN when the run kept neither."""
    v = post.info.get("max_loglik")
    if v is None and post.predictive is not None:
        v = float(np.max(post.predictive.loglik))
    return float("nan") if v is None else float(v)


def pool_runs(
    posts: Sequence[Posterior], *, seed: int = 0, rule: str = "loglik", gap: float | None = None
) -> Posterior:
    """Pool finished runs of the same target by ``rule`` (module docstring), leaving out those more than
    ``gap`` nats (default: the rule's, :data:`RUN_RULES`) below the best run.

    ``info["runs"]`` lists every run (seed when known, log evidence, simulations, best particle's
    log-likelihood, kept or not); ``info["runs_kept"]`` counts those pooled."""
    posts = list(posts)
    if not posts:
        raise ValueError("pool_runs needs at least one run")
    if rule not in RUN_RULES:
        raise ValueError(f"rule must be one of {sorted(RUN_RULES)}, got {rule!r}")
    gap = RUN_RULES[rule] if gap is None else gap
    if not gap > 0:
        raise ValueError(f"gap must be a positive number of nats, got {gap}")
    names = posts[0].names
    if any(p.names != names for p in posts):
        raise ValueError("runs to pool must estimate the same parameters")
    lz = np.array([p.log_evidence for p in posts], dtype=float)
    if not np.all(np.isfinite(lz)):
        raise ValueError(f"every run needs a finite log evidence to be pooled, got {lz.tolist()}")
    best = np.array([best_loglik(p) for p in posts])
    if rule == "loglik" and not np.all(np.isfinite(best)):
        raise ValueError(f"rule 'loglik' needs each run's best log-likelihood, got {best.tolist()}")
    score = best if rule == "loglik" else lz
    kept = score >= score.max() - gap
    pooled = [p for p, k in zip(posts, kept) if k]
    share = -math.log(len(pooled))
    samples = np.concatenate([p.samples for p in pooled])
    logw = np.concatenate([p.log_weights + share for p in pooled])
    # mean of the runs' Z, and the standard error of that mean, in logs
    z = np.exp(lz - lz.max())
    log_z = float(lz.max() + math.log(z.mean()))
    se = float(z.std(ddof=1) / math.sqrt(z.size) / z.mean()) if z.size > 1 else posts[0].log_evidence_se
    msgs = list(dict.fromkeys(m for p in pooled for m in p.warnings))
    if not kept.all():
        what = "best log-likelihood" if rule == "loglik" else "log evidence"
        msgs.append(
            f"RUNS DISAGREE: {int((~kept).sum())} of {len(posts)} independent runs settled more than {gap:g} "
            f"nats of {what} below the best ({', '.join(f'{v:.1f}' for v in score)}) and were left out; a "
            "sampler that missed a basin once may have missed one in the runs kept too, so the intervals "
            "are not calibrated (docs/inference.md, 'Do the runs agree?')"
        )
    rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(_POOL_KEY,)))
    post = Posterior.from_weighted(
        names,
        samples,
        logw,
        rng=rng,
        log_evidence=log_z,
        log_evidence_se=se,
        n_simulations=sum(p.n_simulations for p in posts),
        n_failed=sum(p.n_failed for p in posts),
        method=posts[0].method,
        check=False,
        warnings=msgs,
        obs_gaw=posts[0].obs_gaw,
        fps=posts[0].fps,
    )
    post.ess = float(sum(p.ess for p in pooled))
    post.pareto_k = float("nan")
    if all(p.predictive is not None and p.predictive_index is not None for p in pooled):
        # predictive row i of a run belongs to its sample predictive_index[i]; shift by the run's offset
        offsets = np.cumsum([0] + [len(p.samples) for p in pooled[:-1]])
        post.predictive = Evaluation.concat([p.predictive for p in pooled])
        post.predictive_index = np.concatenate([p.predictive_index + o for p, o in zip(pooled, offsets)])
    post.area_scale = posts[0].area_scale
    post.model = posts[0].model
    runs = []
    for p, k, b in zip(posts, kept, best):
        runs.append(
            {
                "seed": p.info.get("seed"),
                "log_evidence": float(p.log_evidence),
                "log_evidence_se": float(p.log_evidence_se),
                "n_simulations": int(p.n_simulations),
                "n_generations": int(p.info.get("n_generations", 0)),
                "best_loglik": float(b),
                "kept": bool(k),
            }
        )
    post.info.update(
        {
            "runs": runs,
            "runs_kept": len(pooled),
            "run_rule": rule,
            "run_gap": float(gap),
            "max_loglik": float(np.nanmax(best)) if np.any(np.isfinite(best)) else float("nan"),
            "n_particles": sum(int(p.info.get("n_particles", len(p.samples))) for p in pooled),
        }
    )
    return post
