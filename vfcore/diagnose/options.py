"""The settings of a diagnosis: one frozen object, the only source of their defaults and bounds.

:func:`vfcore.diagnose.diagnose`, ``vfinfer diagnose`` and ``POST /jobs/{id}/diagnose`` all read their
defaults from :class:`DiagnoseOptions` and their bounds from :data:`BOUNDS`, so the library runs the
same diagnosis as the command line and the service. The defaults are the settings the
concealed-effect benchmark measures (``benchmarks/bench_diagnose.py``, :ref:`validation-diagnose`):
a benchmark run with other settings than the user's would measure another tool.
"""

from __future__ import annotations

import dataclasses
import operator
from dataclasses import dataclass

from .adequacy import MAX_RMS_RATIO

__all__ = ["DiagnoseOptions", "BOUNDS", "OBSERVATION_ENTRIES", "REFIT_STARTS", "RESCUE_METHODS"]

#: The observation-level entries of the catalogue (:mod:`.extensions`): more refits than these cannot
#: be asked for (tests/service/test_cli_diagnose.py checks the count against the catalogue).
OBSERVATION_ENTRIES = 6

#: ``(low, high)`` of each bounded setting, inclusive; ``None`` is no limit on that side. SMC refuses
#: fewer than 10 particles (:class:`vfcore.inference.smc.SMCSampler`) and every base fit and refit is
#: one, so a smaller count would fail the diagnosis when it reaches that stage.
BOUNDS = {
    "n_particles": (10, 400),
    "refit_particles": (10, 400),
    "max_refits": (0, OBSERVATION_ENTRIES),
    "continuation_entries": (1, None),
    "base_runs": (1, None),
    "mode_checks": (0, None),
    "escalate_factor": (1, None),
    "seed": (0, 2**63 - 1),
    "chunk_size": (1, None),
}

#: How a refit that ended far below the base is refitted (:mod:`.rescue`).
RESCUE_METHODS = ("reference", "box")

#: Where the refits' SMC starts (:mod:`.refits`): the prior; the base posterior (the rescue's
#: reference-started SMC) for every entry; or for the observation-level entries only.
REFIT_STARTS = ("prior", "base", "mixed")


@dataclass(frozen=True)
class DiagnoseOptions:
    """Every setting of :func:`vfcore.diagnose.diagnose`; :ref:`diagnose` explains each stage.

    The defaults are the command line's and the service's (they were the benchmark's settings
    before the library shared them): 40 base particles, 24 refit particles, continuation on for
    the 5 refitted entries of largest evidence, material first. ``DiagnoseOptions(**kw)`` checks
    every setting once; ``options.replace(**kw)`` returns a checked copy.

    Attributes
    ----------
    candidates : sequence of str or None
        Catalogue entries to screen (None: every implemented one; unimplemented ones are skipped).
    n_particles : int
        SMC particles of each base fit (:func:`.baseline.base_fit`, ``base_runs`` independent runs,
        the largest log-evidence kept).
    seed : int
        Seed of the whole diagnosis; every stage derives its own from it.
    chunk_size : int
        Rows of parameters per part handed to ``map``.
    max_refits : int or None
        Most observation-level refits, best screened first (None: all).
    screen_min : float or None
        Refit only observation-level entries whose screening score (nats) exceeds it (None: no
        cut; the score holds the material parameters at the base's, so an effect the base absorbs
        screens at or below zero).
    min_gain, k_se, min_rms_gain, null_sd : float
        The naming rule (:mod:`.rank`): a log-evidence gain above ``min_gain`` nats and ``k_se``
        standard errors, a residual RMS at least ``min_rms_gain`` lower, parameters not within
        ``null_sd`` sd of their null value.
    base_runs : int
        Independent base SMC runs, each seeded by its own child of the base stage's ``SeedSequence``
        (:mod:`vfcore.diagnose.seeds`).
    mode_checks : int
        Before a winner is named the base model is re-fitted around its material mode
        (:func:`.mode_fits.base_near`), at most this many times (0: off).
    local_check : bool
        A candidate failing only because the between-run error swamps its gain is compared with
        the base model refitted in its own mode (:func:`.amend.promote_local`).
    smc_options : dict or None
        Further keyword arguments of every SMC run.
    screen_options : dict or None
        Keyword arguments of :func:`.screen.screen`.
    refit_forward : bool
        Refit every forward-level entry whatever its screening score (the score of an entry that
        only pays off with a shift of the material parameters is not informative).
    refit_particles : int or None
        SMC particles of the refits, mode checks and rescues (None: ``n_particles``).
    refit_start : {"prior", "base", "mixed"}
        ``"prior"``: each refit's SMC starts from the prior of materials x extension; ``"base"``: from
        the base posterior, as the reference-started rescue does (:func:`.mode_fits.base_reference`,
        inflated ``rescue_inflate`` times); ``"mixed"``: the observation-level entries from the base
        posterior, the forward-level ones from the prior. A refit started from the base is not
        rescued by the same method again. ``"prior"`` stays the default: on nine scored cases the base
        start saved 28 % of the simulations and named one effect fewer right and two more wrong
        (:ref:`validation-diagnose-pipeline-refits-started-from-the-base`).
    escalate_tau : float or None
        When the base runs' between-run error exceeds this (nats), more base runs are made with
        ``escalate_factor`` times the particles, and every later fit uses that factor too
        (None: never).
    escalate_factor : int
        Particle factor of the escalation.
    escalate_refits : bool
        An escalation also multiplies the particles of every later refit, rescue, mode check and
        continued fit (False: only the base runs are escalated).
    integrate : bool
        Refits integrate each extension's waveform-level parameters out of every simulation's
        likelihood by quadrature (:func:`.fit.fit_extended`); False: the SMC is joint.
    nested_check : bool
        A winner sitting where it reduces to a simpler entry is compared with that entry refitted
        in its mode (:func:`.amend.prefer_nested`).
    parsimony_se : float
        A found entry with fewer parameters within this many standard errors of the winner is named
        instead (:func:`.amend.prefer_parsimonious`; 0: off, the evidence has its own Occam factor).
    rescue_forward, rescue_observation : bool
        Refit a forward- / observation-level refit that ended more than ``max(min_gain, k_se se)``
        below the base (it missed the base-like region of its own model) near the base's mode.
    rescue_half_width : float
        Half-width of the box rescue, fraction of each material parameter's prior width.
    rescue_method : {"reference", "box"}
        ``"reference"``: an SMC started from the base posterior (an evidence estimate);
        ``"box"``: an SMC on a box around it (a lower bound).
    rescue_inflate : float
        Sd factor of the Gaussian reference of the reference-started refits.
    regularity_check : bool
        Re-simulate the base fit's heaviest particle slightly moved (:mod:`.regularity`); a rough
        likelihood counts as an error of the local check.
    best_of_base : bool
        On an irregular base fit with nothing named, rank once more against the best of all
        base-model fits (:func:`.rank.rank_best_of_base`).
    shared_mode : bool
        Refit every entry from the leading refit's material mode too (:mod:`.shared_mode`).
    continuation : bool
        Search the base model and the refitted entries by window continuation and fit from the
        optimum (:mod:`.continuation`; ~2,000 simulations per model).
    continuation_options : dict or None
        Overrides of :data:`.search.CONTINUATION`.
    free_material : bool
        Free the scaled parameters held at Table 3 before the catalogue is screened
        (:func:`.material.material_first`).
    max_rms_ratio : float or None
        A best fit whose residual RMS exceeds this many times the recording's noise gives "the model
        does not fit" (:mod:`.adequacy`; None: never).
    floor_stop : bool
        Stop before the catalogue when the base fit is so close to the noise that no entry could
        lower its RMS by ``min_rms_gain``.
    continuation_entries : int or None
        Search only this many refitted entries by continuation, those of largest refit evidence
        (None: every one).
    """

    candidates: tuple[str, ...] | None = None
    n_particles: int = 40
    seed: int = 0
    chunk_size: int = 40
    max_refits: int | None = None
    screen_min: float | None = None
    min_gain: float = 3.0
    k_se: float = 3.0
    min_rms_gain: float = 0.30
    null_sd: float = 2.0
    base_runs: int = 2
    mode_checks: int = 2
    local_check: bool = True
    smc_options: dict | None = None
    screen_options: dict | None = None
    refit_forward: bool = True
    refit_particles: int | None = 24
    refit_start: str = "prior"
    escalate_tau: float | None = 10.0
    escalate_factor: int = 2
    escalate_refits: bool = True
    integrate: bool = True
    nested_check: bool = True
    parsimony_se: float = 0.0
    rescue_forward: bool = True
    rescue_observation: bool = True
    rescue_half_width: float = 0.15
    rescue_method: str = "reference"
    rescue_inflate: float = 2.0
    regularity_check: bool = True
    best_of_base: bool = True
    shared_mode: bool = False
    continuation: bool = True
    continuation_options: dict | None = None
    free_material: bool = True
    max_rms_ratio: float | None = MAX_RMS_RATIO
    floor_stop: bool = True
    continuation_entries: int | None = 5

    def __post_init__(self):
        if self.rescue_method not in RESCUE_METHODS:
            raise ValueError(f"rescue_method must be 'reference' or 'box', got {self.rescue_method!r}")
        if self.refit_start not in REFIT_STARTS:
            raise ValueError(
                f"refit_start must be one of {', '.join(map(repr, REFIT_STARTS))}, got {self.refit_start!r}"
            )
        from ..inference.smc import WHOLE_RUN_OPTIONS

        whole = sorted(set(self.smc_options or {}) & set(WHOLE_RUN_OPTIONS))
        if whole and self.refit_start != "prior":
            raise ValueError(
                f"refits started from the base posterior run together, so the SMC options {whole} "
                "need refit_start='prior'"
            )
        for name, (lo, hi) in BOUNDS.items():
            v = getattr(self, name)
            if v is None and name not in ("n_particles", "seed", "base_runs", "chunk_size"):
                continue
            if not _whole(v) or (lo is not None and v < lo) or (hi is not None and v > hi):
                span = f"{lo} to {hi}" if hi is not None else f">= {lo}"
                raise ValueError(f"{name} must be an integer {span}, got {v!r}")
        if self.candidates is not None:
            object.__setattr__(self, "candidates", tuple(self.candidates))

    def replace(self, **changes) -> DiagnoseOptions:
        """A checked copy with ``changes``; an unknown name raises TypeError naming it."""
        known = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(changes) - known)
        if unknown:
            raise TypeError(f"unknown diagnosis option(s) {unknown}")
        return dataclasses.replace(self, **changes)

    @property
    def refit_n(self) -> int:
        """SMC particles of a refit before any escalation."""
        return self.refit_particles or self.n_particles


def _whole(v) -> bool:
    """An integer (a numpy one too), not a bool."""
    if isinstance(v, bool):
        return False
    try:
        operator.index(v)
    except TypeError:
        return False
    return True
