"""What the stages of a diagnosis hand each other: the run's fixed settings (:class:`Run`) and the
results so far (:class:`DiagnosisState`). Every stage is a function ``stage(run, state)`` that reads
both and adds its results to the state, so what a stage depends on is in its arguments, not in
variables shared by closures."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from ..inference.posterior import Posterior
from ..inference.problem import Problem
from .options import DiagnoseOptions
from .progress import ProgressTracker
from .summary import fit_summary

__all__ = ["Run", "DiagnosisState"]


@dataclass(frozen=True)
class Run:
    """The settings every stage reads and none changes.

    ``map`` is the caller's map wrapped by ``track`` (it counts rows, changes nothing); ``t0`` the
    start, s (``time.perf_counter``)."""

    options: DiagnoseOptions
    map: Callable
    track: ProgressTracker
    t0: float

    @classmethod
    def start(cls, options: DiagnoseOptions, map: Callable, progress: Callable[[dict], None] | None) -> Run:
        t0 = time.perf_counter()
        track = ProgressTracker(progress, t0)
        return cls(options=options, map=track.wrap(map), track=track, t0=t0)

    @property
    def smc(self) -> dict:
        """Keyword arguments of every SMC run (a fresh copy)."""
        return dict(self.options.smc_options or {})

    @property
    def rule(self) -> dict:
        """The naming rule's thresholds, as :mod:`.rank` and :mod:`.material` take them."""
        o = self.options
        return dict(min_gain=o.min_gain, k_se=o.k_se, min_rms_gain=o.min_rms_gain)


@dataclass
class DiagnosisState:
    """The results of a diagnosis so far.

    Attributes
    ----------
    problem : Problem
        The problem diagnosed (the freed one once material first kept it).
    base : Posterior or None
        The base fit (None until fitted).
    candidates : list of str
        The implemented catalogue entries screened.
    refit_n : int
        SMC particles of a refit (times the escalation factor once escalated).
    n_simulations : int
        Rows evaluated so far (the report's ``n_simulations``).
    tau, roughness : float
        The between-run error of a log-evidence and the base fit's roughness, nats.
    before, after : dict
        Summaries of the base fit and of each refit (the report's ``base`` and ``refits``).
    refits : dict of str to Posterior
        The kept fit of each refitted entry.
    references : dict
        Further base-model evidences, name -> ``(log Z, se, residual RMS)`` (:mod:`.rank`).
    """

    problem: Problem
    base: Posterior | None
    candidates: list
    refit_n: int
    notes: list = field(default_factory=list)
    n_simulations: int = 0
    tau: float = 0.0
    roughness: float = 0.0
    material: dict | None = None
    before: dict = field(default_factory=dict)
    screening: dict = field(default_factory=dict)
    chosen: list = field(default_factory=list)
    refits: dict = field(default_factory=dict)
    after: dict = field(default_factory=dict)
    references: dict = field(default_factory=dict)
    base_loc: object | None = None

    def summary(self, post: Posterior) -> dict:
        """:func:`.summary.fit_summary` of ``post`` on this problem's recording."""
        return fit_summary(post, self.problem.obs_compared, self.problem.fps)

    def lz(self, post: Posterior) -> tuple[float, float]:
        """``post``'s log-evidence and its error with the between-run error added in quadrature."""
        return float(post.log_evidence), math.hypot(float(post.log_evidence_se), self.tau)
