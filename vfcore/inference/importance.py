"""Bayesian importance sampling with the prior as proposal (Hadwin et al. 2019, Section 4.2).

Draws ``theta_i ~ prior`` (i = 1..N, N = 50,000 in the paper); with the prior as proposal the
importance weight of each draw is its likelihood, ``w_i = L_i / sum_j L_j``, computed with
log-sum-exp. The evidence is ``p(y) ~ mean(L_i)``. Posterior summaries use the weights
directly; a systematic resample gives an equally weighted ensemble for predictive products.

The pieces are pure so a distributed worker can run them chunk by chunk:
``draw_prior`` -> ``chunks`` -> ``evaluate`` (per chunk) -> ``reduce_importance``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np

from .diagnostics import log_evidence_is
from .posterior import Posterior
from .prior import Prior
from .problem import Evaluation, Problem, ProblemEvaluator, model_record

DEFAULT_DRAWS = 50_000

# SeedSequence children of the run seed (fixed order: never reorder)
_DRAW, _RESAMPLE = 0, 1


def seed_children(seed: int | np.random.SeedSequence, n: int = 2) -> list[np.random.SeedSequence]:
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    return ss.spawn(n)


def draw_prior(prior: Prior, n: int, seed: int) -> np.ndarray:
    """``n`` prior draws (n, d); deterministic in ``seed``."""
    if int(n) < 1:
        raise ValueError(f"number of draws must be >= 1, got {n}")
    return prior.sample(int(n), np.random.default_rng(seed_children(seed)[_DRAW]))


def chunks(thetas: np.ndarray, chunk_size: int) -> list[np.ndarray]:
    """Split rows of ``thetas`` into consecutive chunks of at most ``chunk_size`` rows."""
    chunk_size = max(1, int(chunk_size))
    return [thetas[i : i + chunk_size] for i in range(0, thetas.shape[0], chunk_size)]


def batch_function(target) -> Callable:
    """The batch function ``thetas -> Evaluation | loglik array`` for a Problem or a callable."""
    if isinstance(target, Problem):
        return ProblemEvaluator(target)
    if callable(target):
        return target
    raise ValueError(f"target must be a Problem or a callable thetas -> logliks, got {type(target).__name__}")


def resolve_target(target, prior: Prior | None) -> tuple[Prior, np.ndarray | None, float | None, Callable]:
    """(prior, compared observation, fps, batch log-likelihood) of a sampler's target.

    A ``Problem`` supplies its own prior (unless one is given) and observation; a plain
    log-likelihood callable needs ``prior`` and has no observation.
    """
    if isinstance(target, Problem):
        prior = target.prior if prior is None else prior
        obs, fps = target.obs_compared, target.fps
    else:
        obs, fps = None, None
    if prior is None:
        raise ValueError("a prior is needed when the target is a plain log-likelihood function")
    return prior, obs, fps, batch_function(target)


class BalancedMap:
    """``map`` for :func:`map_evaluate` that re-splits each batch into ``workers`` contiguous, equal
    parts for ``inner`` (a pool's map), then cuts the results back into one Evaluation per part it was
    given (row order kept): callers count one result per part.

    Why: a sampler's batch is cut into chunks of a fixed size, so on 2 workers a 24-particle SMC
    generation at chunk size 20 goes out as 20 + 4 rows and one worker idles most of the time, and
    at chunk size 10 as 10 + 10 + 4. Equal parts, one per worker, finish together, and each is one
    larger lock-step block (:func:`vfcore.batch.simulate_many`), which runs faster per simulation.
    A row's result does not depend on the rows simulated beside it, so the split changes no result
    (tests/vfcore/inference/test_balanced_map.py). ``workers``: an int, or a callable read at
    each batch (a cluster that grows or shrinks).

    A batch function with ``row_tasks = True`` (a continuation search's starts: each row a
    Nelder-Mead run of hundreds of simulations, of unequal length) gets one row a part instead,
    so the pool hands the next start to whichever worker is free; equal parts of such rows would
    leave a worker idle while the other finishes its longer share."""

    def __init__(self, inner: Callable, workers):
        self.inner, self.workers = inner, workers

    def _n(self) -> int:
        w = self.workers() if callable(self.workers) else self.workers
        return max(1, int(w))

    def __call__(self, fn, parts):
        parts = [np.atleast_2d(p) for p in parts]
        if not parts:
            return []
        rows = np.concatenate(parts)
        if rows.shape[0] == 0:
            return [Evaluation.coerce(r) for r in self.inner(fn, parts)]
        n = rows.shape[0] if getattr(fn, "row_tasks", False) else min(self._n(), rows.shape[0])
        ev = Evaluation.concat([Evaluation.coerce(r) for r in self.inner(fn, np.array_split(rows, n))])
        edges = np.cumsum([0] + [p.shape[0] for p in parts])
        return [ev.take(np.arange(a, b)) for a, b in zip(edges[:-1], edges[1:])]


def map_evaluate(fn: Callable, thetas: np.ndarray, map: Callable = map, chunk_size: int = 256) -> Evaluation:
    """Evaluate ``fn`` on ``thetas`` in chunks through the given ``map``; concatenated Evaluation."""
    thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
    if thetas.shape[0] == 0:
        return Evaluation(loglik=np.empty(0), ok=np.empty(0, bool))
    parts = list(map(fn, chunks(thetas, chunk_size)))
    ev = Evaluation.concat(parts)
    if len(ev) != thetas.shape[0]:
        raise RuntimeError(f"batch function returned {len(ev)} results for {thetas.shape[0]} draws")
    return ev


def reduce_importance(
    thetas,
    logliks,
    names: Iterable[str],
    seed: int,
    *,
    n_resample: int | None = None,
    ess_min: float = 100.0,
    n_simulations: int | None = None,
    obs_gaw=None,
    fps: float | None = None,
) -> Posterior:
    """Turn prior draws and their log-likelihoods (array or Evaluation) into a Posterior.

    ``seed`` must be the run seed (the resampling stream is its second SeedSequence child).
    Warns (DegenerateEnsembleWarning) when ESS < ``ess_min`` or Pareto-k > 0.7.
    """
    ev = Evaluation.coerce(logliks)
    thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
    if len(ev) != thetas.shape[0]:
        raise ValueError(f"{thetas.shape[0]} draws but {len(ev)} log-likelihoods")
    logz, logz_se = log_evidence_is(ev.loglik)
    rng = np.random.default_rng(seed_children(seed)[_RESAMPLE])
    post = Posterior.from_weighted(
        tuple(names),
        thetas,
        ev.loglik,
        rng=rng,
        n_resample=n_resample,
        log_evidence=logz,
        log_evidence_se=logz_se,
        n_simulations=thetas.shape[0] if n_simulations is None else n_simulations,
        n_failed=ev.n_failed,
        method="importance",
        ess_min=ess_min,
        obs_gaw=obs_gaw,
        fps=fps,
    )
    if ev.gaw is not None:
        keep = np.unique(post.resampled)
        post.predictive = ev.take(keep)
        post.predictive_index = keep
    if ev.messages:
        post.info["failure_messages"] = list(ev.messages[:20])
    post.info["max_loglik"] = float(np.max(ev.loglik))
    return post


def importance_sample(
    target,
    prior: Prior | None = None,
    n: int = DEFAULT_DRAWS,
    seed: int = 0,
    *,
    map: Callable = map,
    chunk_size: int = 256,
    n_resample: int | None = None,
    ess_min: float = 100.0,
) -> Posterior:
    """Prior-as-proposal importance sampling.

    ``target``: a ``Problem`` (FE forward model) or a callable ``thetas (k, d) -> loglik (k,)``
    (then ``prior`` is required). ``map`` runs the chunks (builtin ``map``, a process pool's
    ``map``, or a Dask-backed callable). Deterministic for a given ``seed``.
    """
    prior, obs, fps, fn = resolve_target(target, prior)
    thetas = draw_prior(prior, n, seed)
    ev = map_evaluate(fn, thetas, map=map, chunk_size=chunk_size)
    post = reduce_importance(
        thetas, ev, prior.names, seed, n_resample=n_resample, ess_min=ess_min, obs_gaw=obs, fps=fps
    )
    post.info["n_draws"] = int(n)
    post.model = model_record(target)
    return post
