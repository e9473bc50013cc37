"""Several extended fits run together: every generation of every fit goes to the map as one batch.

A refit is a tempered SMC of 24–48 particles (:ref:`diagnose-pipeline-refit`). Run one after another, each
generation reaches the workers as a few rows: on 2 workers, lock-step blocks of about 12 rows, which cost
0.7–0.9 of the scalar kernel per simulation, against 0.4–0.5 for blocks of 32–64 (:ref:`model`,
"Speed"); on a cluster, at most one generation's rows are busy at a time. Run together, the rows of every
fit's pending batch are one batch (:class:`ExtendedPool`): all entries simulate the base model or a
configuration that differs from it only in per-row fields (``vfcore.batch.PER_SAMPLE_FIELDS``), so the
rows of different entries share lock-step blocks.

Each fit is the one :func:`.fit.fit_extended` gives alone, bit for bit: an SMC sampler's randomness is
its own seed's (:class:`vfcore.inference.smc.SMCSampler`), and a row's simulation does not depend on
the rows simulated beside it (``tests/vfcore/test_batch.py``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np

from ..inference.evaluation import Evaluation
from ..inference.importance import map_evaluate
from ..inference.posterior import Posterior
from ..inference.problem import Problem
from ..inference.smc import WHOLE_RUN_OPTIONS
from .fit import ExtendedEvaluator, finish_extended, simulate_rows

__all__ = ["ExtendedPool", "fit_extended_many"]


class ExtendedPool:
    """Picklable batch function over the draws of several extended models of one problem.

    A row is ``(j, theta_j...)``: the index of its evaluator, then that evaluator's parameters (NaN
    after its last). Every row's simulations go through one ``simulate_many`` call, in lock-step blocks
    shared across the evaluators; each evaluator then scores its own rows. The Evaluation has the rows'
    order; ``extra`` is padded with NaN to the widest evaluator's (:meth:`take` cuts a job's back)."""

    def __init__(self, evaluators: Sequence[ExtendedEvaluator]):
        self.evaluators = tuple(evaluators)
        if not self.evaluators:
            raise ValueError("need at least one evaluator")
        if len({id(ev.problem) for ev in self.evaluators}) != 1:
            raise ValueError("the evaluators of a pool must share one problem")
        self.dims = tuple(int(ev.prior.ndim) for ev in self.evaluators)
        self.widths = tuple(3 * len(ev.integrated) if ev.integrated else None for ev in self.evaluators)

    def rows(self, batches: Sequence[tuple[int, np.ndarray]]) -> tuple[np.ndarray, list[np.ndarray]]:
        """The pooled rows of ``batches`` (``(j, thetas)`` pairs) and, per batch, the indices of its rows.

        The batches are interleaved (one row of each in turn), so that equal parts of the pool
        (:class:`vfcore.inference.importance.BalancedMap`) hold every entry's rows alike; the entries'
        scoring costs differ several-fold (integrated parameters)."""
        order: list[tuple[int, int]] = []
        longest = max((th.shape[0] for _, th in batches), default=0)
        for r in range(longest):
            order += [(b, r) for b, (_, th) in enumerate(batches) if r < th.shape[0]]
        out = np.full((len(order), 1 + max(self.dims)), np.nan)
        where: list[list[int]] = [[] for _ in batches]
        for k, (b, r) in enumerate(order):
            j, th = batches[b]
            out[k, 0] = j
            out[k, 1 : 1 + self.dims[j]] = th[r]
            where[b].append(k)
        return out, [np.asarray(w, dtype=np.int64) for w in where]

    def take(self, ev: Evaluation, j: int, idx: np.ndarray) -> Evaluation:
        """Evaluator ``j``'s rows ``idx`` of a pooled Evaluation, as its own call would have returned them."""
        e = ev.take(idx)
        w = self.widths[j]
        return dataclasses.replace(e, extra=None if w is None else e.extra[:, :w])

    def __call__(self, rows) -> Evaluation:
        rows = np.atleast_2d(np.asarray(rows, dtype=float))
        jobs = rows[:, 0].astype(np.int64)
        plans, sim_rows, sim_cfgs = [], [], []
        for j in np.unique(jobs):
            ev = self.evaluators[j]
            sel = np.flatnonzero(jobs == j)
            splits, base_params, phis = ev._draws(rows[sel, 1 : 1 + self.dims[j]])
            pairs = bool(ev.integrated)
            r, c, slots = ev._plan(base_params, phis, pairs)
            plans.append((j, sel, splits, phis, slots, len(sim_rows), len(r), pairs))
            sim_rows += r
            sim_cfgs += c
        sims = simulate_rows(sim_rows, sim_cfgs)
        width = max((w for w in self.widths if w is not None), default=None)
        parts, order = [], []
        for j, sel, splits, phis, slots, at, n, pairs in plans:
            ev = self.evaluators[j]
            e = ev._score(ev._assemble(sims[at : at + n], slots, phis, pairs), splits)
            if width is not None:
                x = np.full((len(sel), width), np.nan)
                if e.extra is not None:
                    x[:, : e.extra.shape[1]] = e.extra
                e = dataclasses.replace(e, extra=x)
            parts.append(e)
            order.append(sel)
        whole = Evaluation.concat(parts)
        inverse = np.empty(rows.shape[0], dtype=np.int64)
        inverse[np.concatenate(order)] = np.arange(rows.shape[0])
        return whole.take(inverse)


def fit_extended_many(
    problem: Problem,
    jobs: Sequence[tuple],
    *,
    map: Callable = map,
    chunk_size: int = 40,
    integrate: bool = True,
    on_done: Callable[[int, Posterior], None] | None = None,
    **smc_options,
) -> list[Posterior]:
    """The fits :func:`.fit.fit_extended` of ``jobs`` (``(extension, n_particles, seed)`` each, or with a
    fourth item, a dict of that fit's own sampler options such as its ``reference``), run together: at each round the pending batch of every unfinished fit goes to ``map`` as one batch of
    :class:`ExtendedPool` rows. Returns the posteriors in ``jobs`` order, each equal to its fit alone;
    ``on_done(i, posterior)`` is called as fit ``i`` finishes. ``smc_options`` are the sampler's
    (:class:`vfcore.inference.smc.SMCSampler`; ``vfcore.inference.smc.WHOLE_RUN_OPTIONS`` are refused)."""
    from ..inference.smc import SMCSampler, run_together

    bad = sorted(set(smc_options) & set(WHOLE_RUN_OPTIONS))
    if bad:
        raise ValueError(f"fits run together take the sampler's options only; not {bad}")
    smc_options = {k: v for k, v in smc_options.items() if k != "symmetry"}  # no scale group: not a Problem
    evs = [ExtendedEvaluator(problem, job[0], integrate=integrate) for job in jobs]
    pool = ExtendedPool(evs)
    samplers = [
        SMCSampler(ev.prior, int(job[1]), int(job[2]), **{**smc_options, **(job[3] if len(job) > 3 else {})})
        for ev, job in zip(evs, jobs)
    ]
    posts: list = [None] * len(jobs)

    def evaluate(pending):
        rows, where = pool.rows(pending)
        ev = map_evaluate(pool, rows, map=map, chunk_size=chunk_size)
        return [pool.take(ev, i, idx) for (i, _), idx in zip(pending, where)]

    def finish(i: int) -> None:
        post = samplers[i].result()
        post.area_scale = None  # what smc() records of a target that is not a Problem
        post.model = None
        posts[i] = finish_extended(post, problem, evs[i])
        if on_done is not None:
            on_done(i, posts[i])

    run_together(samplers, evaluate, finish)
    return posts
