"""BalancedMap: every batch in equal parts, one per worker, with the results of plain chunks."""

from __future__ import annotations

import numpy as np

from vfcore.config import SimConfig
from vfcore.diagnose.progress import ProgressTracker
from vfcore.forward import simulate
from vfcore.inference import Prior, Problem, ProblemEvaluator
from vfcore.inference.importance import BalancedMap, map_evaluate
from vfcore.inference.problem import Evaluation
from vfcore.params import TABLE3


def _loglik(rows):
    return Evaluation.from_loglik(-np.sum(np.asarray(rows) ** 2, axis=1))


def _recording_map(seen):
    def imap(fn, parts):
        parts = list(parts)
        seen.append([p.shape[0] for p in parts])
        return map(fn, parts)

    return imap


def test_one_result_per_part_whatever_the_pool_split():
    """The pool gets the rows in ``workers`` equal parts; the caller gets one result per part it
    gave, in order, which is what the diagnosis' progress tracker counts."""
    seen = []
    bm = BalancedMap(_recording_map(seen), 2)
    rows = np.arange(36.0).reshape(18, 2)
    want = _loglik(rows).loglik
    for chunk in (18, 7, 100):
        ev = map_evaluate(_loglik, rows, map=ProgressTracker(None, 0.0).wrap(bm), chunk_size=chunk)
        np.testing.assert_array_equal(ev.loglik, want)
    assert seen == [[9, 9]] * 3


def test_worker_count_is_read_at_each_batch_and_never_exceeds_the_rows():
    seen = []
    n = [3]
    bm = BalancedMap(_recording_map(seen), lambda: n[0])
    map_evaluate(_loglik, np.ones((10, 1)), map=bm, chunk_size=4)
    n[0] = 5
    map_evaluate(_loglik, np.ones((2, 1)), map=bm, chunk_size=4)
    assert seen == [[4, 3, 3], [1, 1]]
    assert bm(_loglik, []) == []


class _LongRows:
    """A batch function whose rows are long jobs of their own (a continuation start)."""

    row_tasks = True

    def __call__(self, rows):
        return _loglik(rows)


def test_rows_that_are_long_jobs_go_to_the_pool_one_a_part():
    """A continuation search's starts run hundreds of simulations each, for unequal times: the pool
    gets them one a part (it hands each to the next free worker), and the caller still one result per
    part it gave, with the same values."""
    seen = []
    bm = BalancedMap(_recording_map(seen), 2)
    rows = np.arange(14.0).reshape(7, 2)
    ev = map_evaluate(_LongRows(), rows, map=ProgressTracker(None, 0.0).wrap(bm), chunk_size=1)
    np.testing.assert_array_equal(ev.loglik, _loglik(rows).loglik)
    ev = map_evaluate(_LongRows(), rows, map=bm, chunk_size=3)
    np.testing.assert_array_equal(ev.loglik, _loglik(rows).loglik)
    assert seen == [[1] * 7, [1] * 7]


def test_fe_rows_give_the_same_bits_in_balanced_parts_as_in_fixed_chunks():
    """24 FE rows as 20 + 4 (a lock-step block of 20, four rows on the scalar kernel) and as 12 + 12
    (two lock-step blocks): a row's log-likelihood and GAW do not depend on the rows beside it."""
    cfg = SimConfig(mesh="coarse", dt=1e-4, duration=0.12, discard=0.04)
    prior = Prior({"E_cover": (450.0, 900.0), "p_sub": (700.0, 1300.0)})
    y = simulate(TABLE3, cfg).gaw
    pb = Problem(y + np.random.default_rng(1).normal(0.0, 0.5, y.size), cfg.fps, prior, sigma_e=1.0, config=cfg)
    rows = prior.sample(24, np.random.default_rng(7))
    seen = []
    chunked = map_evaluate(ProblemEvaluator(pb), rows, map=_recording_map(seen), chunk_size=20)
    balanced = map_evaluate(ProblemEvaluator(pb), rows, map=BalancedMap(_recording_map(seen), 2), chunk_size=20)
    assert seen == [[20, 4], [12, 12]]
    assert np.isfinite(chunked.loglik).sum() >= 20
    np.testing.assert_array_equal(balanced.loglik, chunked.loglik)
    np.testing.assert_array_equal(balanced.gaw, chunked.gaw)
