"""Every request and response body of the REST API, and the diagnosis settings the CLI shares with it.

The routes and the command line import their types and bounds from here (and never from each other), so
``vfinfer diagnose``, ``vfinfer diagnosis --start`` and ``POST /jobs/{id}/diagnose`` accept exactly the same
settings. An inference job's body is :class:`worker.jobspec.JobSpec` (the worker stores and re-runs it), re-exported
here so that the API's types are read in one place.
"""

from __future__ import annotations

from enum import Enum
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from vfcore.diagnose.options import BOUNDS, OBSERVATION_ENTRIES, REFIT_STARTS, DiagnoseOptions
from worker.jobspec import JobSpec

__all__ = [
    "JobSpec",
    "Figure",
    "Submitted",
    "JobStatus",
    "CompareRequest",
    "LinkOut",
    "DiagnoseRequest",
    "DiagnosisSpec",
    "DiagnoseStarted",
    "ExpectedDiagnosis",
    "DiagnosisStatus",
    "check_candidates",
    "KINDS",
    "DIAGNOSIS_OPTIONS",
]

#: What a row of the job table holds: an inference (a JobSpec) or a diagnosis of a finished inference.
KINDS = ("inference", "diagnosis")


# ------------------------------------------------------------------------------------ inference jobs
class Figure(str, Enum):
    gaw_fit = "gaw_fit"
    corner = "corner"
    contact_pressure = "contact_pressure"


class Submitted(BaseModel):
    id: str
    state: str
    status_url: str
    warnings: list[str] = Field(default_factory=list)
    expected_simulations: tuple[int, int] | None = Field(
        default=None,
        description=(
            "(low, high) simulations the run will take: exact for importance sampling, the range measured on "
            "finite-element fits for SMC (docs/inference.md, 'Cost before a run')"
        ),
    )


class JobStatus(BaseModel):
    id: str
    state: Literal["queued", "running", "done", "failed", "cancelled"]
    progress: dict
    ess: float | None
    timings: dict
    error: str | None = None
    sampler: str
    model: str
    stats: dict = Field(default_factory=dict)
    warnings: list[str] = Field(default_factory=list)
    kind: Literal["inference", "diagnosis"] = Field(
        default="inference", description='"inference" (POST /jobs) or "diagnosis" (POST /jobs/{id}/diagnose)'
    )
    parent: str | None = Field(default=None, description="a diagnosis: the id of the job it diagnoses")


class CompareRequest(BaseModel):
    job_ids: list[str] = Field(min_length=2, max_length=10)


class LinkOut(BaseModel):
    url: str = Field(description="the page's signed link, relative to the service (prefix your service URL)")
    absolute_url: str = Field(description="the same link on the address this request was sent to")
    expires: int = Field(description="when the link stops working, epoch seconds")
    expires_in_s: int = Field(description="how long the link stays valid, seconds")


# ------------------------------------------------------------------------------------ diagnoses
def check_candidates(names) -> list[str]:
    """Unknown or not-implemented extension names raise ValueError naming them."""
    from vfcore.diagnose.extensions import CATALOGUE

    names = list(dict.fromkeys(n.strip() for n in names))
    unknown = [n for n in names if n not in CATALOGUE]
    if unknown:
        raise ValueError(f"unknown candidate(s) {unknown}; known: {sorted(CATALOGUE)}")
    unimpl = [n for n in names if not CATALOGUE[n].implemented]
    if unimpl:
        impl = sorted(n for n, e in CATALOGUE.items() if e.implemented)
        raise ValueError(f"candidate(s) {unimpl} are catalogued but not implemented; fittable: {impl}")
    if not names:
        raise ValueError("no candidates given")
    return names


#: The library's defaults, the only ones (vfcore.diagnose.options).
DEFAULTS = DiagnoseOptions()


def _bounds(name: str) -> dict:
    """``ge``/``le`` of a setting from the library's one table of bounds."""
    lo, hi = BOUNDS[name]
    return {k: v for k, v in (("ge", lo), ("le", hi)) if v is not None}


class DiagnoseRequest(BaseModel):
    """A diagnosis's settings: the body of ``POST /jobs/{id}/diagnose`` and the options of ``vfinfer diagnose``
    and ``vfinfer diagnosis --start``, with one set of bounds for all three. The defaults are
    ``vfcore.diagnose.defaults``, the settings the concealed-effect benchmark measures."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    candidates: list[str] | None = Field(
        default=None,
        min_length=1,
        max_length=50,
        description="catalogued, implemented extensions to screen (default: all implemented ones)",
    )
    n_particles: int = Field(
        default=DEFAULTS.n_particles, **_bounds("n_particles"), description="SMC particles of each base fit"
    )
    refit_particles: int = Field(
        default=DEFAULTS.refit_particles, **_bounds("refit_particles"), description="SMC particles of each extended fit"
    )
    max_refits: int | None = Field(
        default=DEFAULTS.max_refits,
        **_bounds("max_refits"),
        description="most observation-level extensions refitted, best screened "
        f"first (default: all {OBSERVATION_ENTRIES})",
    )
    refit_start: Literal[REFIT_STARTS] = Field(
        default=DEFAULTS.refit_start,
        description="where each extended fit's SMC starts: the prior; the base posterior (fewer simulations, "
        "no rescue); or the base posterior for the observation-level entries only "
        "(docs/diagnose.md, 'Refits started from the base')",
    )
    continuation: bool = Field(
        default=DEFAULTS.continuation,
        description="also search the base model and every extension by window "
        "continuation and fit from the optimum (docs/diagnose.md section 4)",
    )
    free_material: bool = Field(
        default=DEFAULTS.free_material,
        description="free the scaled parameters held at Table 3 (all but the anchor rho) "
        "before the catalogue is screened, and report whether they explain the "
        "mismatch (docs/diagnose.md, 'Material first')",
    )
    reuse_posterior: bool = Field(
        default=True,
        description="start from the diagnosed job's own posterior as the base fit instead "
        "of fitting the base model again (a job that estimated fewer material "
        "parameters is the pinned fit that freeing them is judged against); "
        "the command line's --base",
    )
    seed: int = Field(default=DEFAULTS.seed, **_bounds("seed"))

    @field_validator("candidates")
    @classmethod
    def _known(cls, v):
        return None if v is None else check_candidates(v)

    def settings(self) -> dict:
        """The library settings this request gives (:class:`vfcore.diagnose.DiagnoseOptions` fields; the rest
        keep the library's defaults; ``reuse_posterior`` is the caller's business)."""
        return dict(
            candidates=self.candidates,
            n_particles=self.n_particles,
            refit_particles=self.refit_particles,
            refit_start=self.refit_start,
            max_refits=self.max_refits,
            continuation=self.continuation,
            free_material=self.free_material,
            seed=self.seed,
        )

    def options(self) -> DiagnoseOptions:
        """The library's options of this request."""
        return DEFAULTS.replace(**self.settings())


#: The command-line option of each DiagnoseRequest field (error messages name what the user typed).
DIAGNOSIS_OPTIONS = {
    "candidates": "--candidates",
    "n_particles": "--particles",
    "refit_particles": "--refit-particles",
    "refit_start": "--refit-start",
    "max_refits": "--max-refits",
    "continuation": "--continuation",
    "free_material": "--free-material",
    "reuse_posterior": "--base",
    "seed": "--seed",
}


class DiagnosisSpec(BaseModel):
    """What a diagnosis job stores (its table row and its store): the job it diagnoses, the settings, and how
    its batches are cut, fixed when it was submitted so that a resumed run asks for the same parts its store
    kept: ``parts`` equal parts a batch, one per worker thread of the cluster at submission
    (:class:`vfcore.inference.importance.BalancedMap`), or chunks of ``chunk_size`` rows (both ``None``: one part
    per worker thread of the cluster when it runs)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    version: Literal[1] = 1
    job: str = Field(description="the id of the finished inference job diagnosed")
    request: DiagnoseRequest
    chunk_size: int | None = Field(default=None, ge=1, le=400)
    parts: int | None = Field(default=None, ge=1, le=4096)

    def to_json(self) -> str:
        return self.model_dump_json()


class ExpectedDiagnosis(BaseModel):
    """What a diagnosis is expected to cost, announced when it is queued (vfcore.diagnose.expected): which of
    the two outcomes it ends in is known only after its base fit."""

    floor_simulations: tuple[int, int] = Field(
        description=(
            "(low, high) simulations if the base fit reaches the noise and the diagnosis stops there; (0, 0) when the "
            "job's own posterior is the base fit as it is"
        )
    )
    catalogue_simulations: tuple[int, int] = Field(description="(low, high) simulations if it goes on to the catalogue")
    base_fits: int = Field(
        description="base fits it runs: 0 (the job's posterior reused), 1, or 2 (a pinned fit, "
        "then the parameters held at Table 3 freed)"
    )
    scaled_for: list[str] = Field(
        default_factory=list,
        description=(
            "settings away from the defaults the ranges were measured at (empty: the measured ranges); the figures "
            "are then scaled linearly, a guide"
        ),
    )


class DiagnoseStarted(BaseModel):
    id: str = Field(description="the job diagnosed")
    state: str
    status_url: str
    diagnosis_id: str = Field(description="the diagnosis's own job id (GET or DELETE /jobs/{diagnosis_id})")
    expected: ExpectedDiagnosis | None = None


class DiagnosisStatus(BaseModel):
    state: str = Field(description='"none", "queued", "running", "done", "failed" or "cancelled"')
    error: str | None = None
    report: dict | None = None
    progress: dict | None = Field(
        default=None,
        description=(
            "while running: the stage, the catalogue entry, its place (step of steps), the simulations "
            "evaluated so far and the seconds elapsed (vfcore.diagnose.progress)"
        ),
    )
    diagnosis_id: str | None = Field(default=None, description="the diagnosis's own job id, once there is one")
