"""Progress of a running diagnosis, for the people waiting on it.

A blind diagnosis runs for an hour or more on one core (tens of thousands of forward
simulations, :ref:`diagnose-cost-cost`). :func:`vfcore.diagnose.pipeline.diagnose` accepts
``progress=callback``; the callback receives a dict at each stage and after each batch of
simulations returns:

- ``stage``: ``"base fit"``, ``"regularity check"``, ``"screening"``, ``"refit"``, ``"rescue"``,
  ``"shared mode"``, ``"continuation"``, ``"mode check"``, ``"nested check"`` or ``"done"``;
- ``entry``: the catalogue entry the stage works on (``"base"`` for the base model's
  continuation search, ``"entries"`` for the searches of every continued entry, or the refits of
  every chosen entry, which run together; None where none);
- ``step`` / ``steps``: the entry's place among the stage's entries (None where not counted);
- ``simulations``: forward simulations evaluated through the diagnosis' ``map`` so far (one a
  row, or what the batch function reports for a row that runs many, a continuation search's
  start; rows read back from a resume store count alike); screening's few simulations, run in
  the main process, are not counted;
- ``elapsed_s``: seconds since the diagnosis started.

The tracker also keeps where the time went: :meth:`ProgressTracker.cost` gives the wall time and
the rows evaluated per stage and per entry, which the diagnosis report carries as ``cost``.

The stage sequence depends on the data (rescues, mode checks and the nested check run only when
their triggers fire), so there is no honest "percent done"; ``step`` of ``steps`` is given where
the count is known in advance. Reporting never changes a result: the batch function and parts
reach the inner map unchanged (tests/vfcore/inference/test_memo.py). A callback that raises is
reported once as a warning and then ignored: an hour of simulation is not lost to a display.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable

import numpy as np

__all__ = ["STAGES", "ProgressTracker"]

STAGES = (
    "base fit",
    "regularity check",
    "screening",
    "refit",
    "rescue",
    "shared mode",
    "continuation",
    "mode check",
    "nested check",
    "done",
)


class ProgressTracker:
    """Keeps the current stage and the rows evaluated; calls ``callback`` with the event dict."""

    def __init__(self, callback: Callable[[dict], None] | None, t0: float | None = None):
        self.callback = callback
        self.t0 = time.perf_counter() if t0 is None else t0
        self.stage = "base fit"
        self.entry: str | None = None
        self.step: int | None = None
        self.steps: int | None = None
        self.simulations = 0
        self._broken = False
        self._open = False  # a stage is being timed
        self._since = self.t0
        self._rows_at = 0
        self._stages: dict[str, dict] = {}
        self._entries: dict[str, dict] = {}

    def event(self) -> dict:
        return {
            "stage": self.stage,
            "entry": self.entry,
            "step": self.step,
            "steps": self.steps,
            "simulations": self.simulations,
            "elapsed_s": time.perf_counter() - self.t0,
        }

    def emit(self, **extra) -> None:
        if self.callback is None or self._broken:
            return
        try:
            self.callback({**self.event(), **extra})
        except Exception as exc:  # noqa: BLE001 - a display must not end a diagnosis
            self._broken = True
            warnings.warn(
                f"the progress callback raised {type(exc).__name__}: {exc}; progress is no longer "
                "reported for this diagnosis",
                RuntimeWarning,
                stacklevel=2,
            )

    def at(self, stage: str, entry: str | None = None, step: int | None = None, steps: int | None = None) -> None:
        """Enter ``stage`` (one of :data:`STAGES`) and report it."""
        if stage not in STAGES:
            raise ValueError(f"unknown progress stage {stage!r}; known: {STAGES}")
        self._close()
        self.stage, self.entry, self.step, self.steps = stage, entry, step, steps
        self._open = stage != "done"
        self.emit()

    def _close(self) -> None:
        now = time.perf_counter()
        if self._open:
            rows = self.simulations - self._rows_at
            for book, key in ((self._stages, self.stage), (self._entries, self.entry or "-")):
                d = book.setdefault(key, {"wall_s": 0.0, "simulations": 0, "visits": 0})
                d["wall_s"] += now - self._since
                d["simulations"] += rows
                d["visits"] += 1
        self._since, self._rows_at = now, self.simulations

    def cost(self) -> dict:
        """``{"by_stage": {stage: {"wall_s", "simulations", "visits"}}, "by_entry": {entry: ...}}``
        for the stages closed so far (``"-"``: stages without an entry; ``"base"``: the base
        model's continuation search; ``"entries"``: the continued entries' searches, or the chosen
        entries' refits, run together).
        Rows counted as in the events; screening's own few simulations are in its wall time, not its
        count."""
        return {
            "by_stage": {k: dict(v) for k, v in self._stages.items()},
            "by_entry": {k: dict(v) for k, v in self._entries.items()},
        }

    def wrap(self, inner: Callable) -> Callable:
        """A ``map(fn, parts)`` that passes everything to ``inner`` unchanged and reports after each
        part's result arrives (results in order, one per part, as :func:`map_evaluate` needs).

        A part counts one simulation a row, unless the batch function says what a result cost:
        ``fn.simulations(part, result)`` (a continuation search's row is a start that runs hundreds
        of simulations, and its result carries their number)."""

        def counted(fn, parts):
            parts = list(parts)
            out = []
            cost = getattr(fn, "simulations", None)
            for part, result in zip(parts, inner(fn, parts)):
                out.append(result)
                self.simulations += (
                    int(cost(part, result))
                    if cost is not None
                    else (int(np.shape(part)[0]) if np.ndim(part) >= 1 else 1)
                )
                self.emit()
            if len(out) != len(parts):
                raise RuntimeError(f"the map returned {len(out)} results for {len(parts)} parts")
            return out

        return counted
