"""How far each diagnosis verdict in a test run sits from the naming rule's thresholds.

A verdict that a last-bit change can flip is one whose deciding quantity lies near a threshold
(docs/diagnose.md, "Box refits re-centre a box that cuts the mode off"). Load this as a pytest
plugin to record, for every :func:`vfcore.diagnose.pipeline.diagnose` call made by the tests, the
evidence margin ``dlogZ - max(min_gain, k_se * se)`` and the effect-size margin
``rms_gain - min_rms_gain`` of every ranked entry, and print the leading entry's margins at the end::

    .venv/bin/python -m pytest -p benchmarks.studies.verdict_margins tests/vfcore/diagnose/test_diagnose_fit.py

Set ``VERDICT_MARGINS=path.jsonl`` to keep the records (one JSON object per diagnosis); running the
suite on two installs (the lock and the oldest allowed versions) and comparing the files shows
whether any verdict moved.
"""

from __future__ import annotations

import functools
import json
import math
import os

_records: list[dict] = []


def _record(rep) -> dict:
    rk = rep.ranking
    rows = []
    for r in rk.rows:
        rms = r.rms_gain if math.isfinite(r.rms_gain) else None
        rows.append(
            {
                "name": r.name,
                "found": bool(r.found),
                "null_consistent": bool(r.null_consistent),
                "evidence_margin": float(r.delta - max(rk.min_gain, rk.k_se * r.delta_se)),
                "rms_margin": None if rms is None else float(rms - rk.min_rms_gain),
            }
        )
    return {
        "test": os.environ.get("PYTEST_CURRENT_TEST", "?").removesuffix(" (call)"),
        "winner": rep.winner,
        "rows": rows,
    }


def pytest_configure(config):
    from vfcore.diagnose import pipeline

    real = pipeline.diagnose

    @functools.wraps(real)
    def recorded(*args, **kwargs):
        rep = real(*args, **kwargs)
        _records.append(_record(rep))
        return rep

    pipeline.diagnose = recorded


def pytest_terminal_summary(terminalreporter):
    if not _records:
        return
    path = os.environ.get("VERDICT_MARGINS")
    if path:
        with open(path, "a") as f:
            for r in _records:
                f.write(json.dumps(r) + "\n")
    tr = terminalreporter
    tr.section("diagnosis verdicts: margins from the naming thresholds")
    tr.write_line(f"{'test':72s} {'winner':10s} {'leading entry':12s} {'dlogZ margin':>12s} {'RMS margin':>10s}")
    for r in _records:
        lead = r["rows"][0] if r["rows"] else None
        ev = f"{lead['evidence_margin']:+.1f}" if lead else "-"
        rms = f"{lead['rms_margin']:+.3f}" if lead and lead["rms_margin"] is not None else "-"
        tr.write_line(
            f"{r['test'][-72:]:72s} {str(r['winner']):10s} {lead['name'] if lead else '-':12s} {ev:>12s} {rms:>10s}"
        )
