"""The benchmark runner's balanced map (benchmarks/bench_diagnose.py)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks.bench_diagnose import BalancedMap  # noqa: E402
from vfcore.diagnose.progress import ProgressTracker  # noqa: E402
from vfcore.inference.importance import map_evaluate  # noqa: E402
from vfcore.inference.problem import Evaluation  # noqa: E402


def _loglik(rows):
    return Evaluation.from_loglik(-np.sum(np.asarray(rows) ** 2, axis=1))


def test_one_result_per_part_whatever_the_pool_split():
    """The pool gets the rows in ``workers`` equal parts; the caller gets one result per part it
    gave, in order — what the diagnosis' progress tracker counts (it used to keep only the first
    half of a one-chunk batch)."""
    seen = []

    def imap(fn, parts):
        parts = list(parts)
        seen.append([p.shape[0] for p in parts])
        return map(fn, parts)

    bm = BalancedMap(imap, 2)
    rows = np.arange(36.0).reshape(18, 2)
    want = _loglik(rows).loglik
    for chunk in (18, 7, 100):
        ev = map_evaluate(_loglik, rows, map=ProgressTracker(None, 0.0).wrap(bm), chunk_size=chunk)
        np.testing.assert_array_equal(ev.loglik, want)
    assert seen[0] == [9, 9]
