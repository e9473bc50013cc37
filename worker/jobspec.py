"""The job specification shared by the service, the worker and the CLI.

One versioned, JSON-serialisable pydantic model.  It is validated once at the edge (HTTP body,
CLI arguments) and stored verbatim in the job's Zarr attributes, so a job can always be
re-run from its store alone.  Validation errors name the offending field (pydantic ``loc``).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    FiniteFloat,
    PrivateAttr,
    ValidationError,
    field_validator,
    model_validator,
)

from vfcore.config import CONTACT_LAYER_MM, CONTACTS, MESHES
from vfcore.params import PARAM_NAMES

#: Bump when the meaning of a field changes; stored jobs carry the version they were made with.
SCHEMA_VERSION = 1

#: Absurd-size guards (the HTTP layer also limits the body size).
MAX_FRAMES = 200_000
MAX_SIMULATIONS = 1_000_000
MAX_SMC_GENERATIONS = 100
MAX_SMC_RUNS = 8


class _Derived:
    """What a spec derives from its fields at validation and keeps (the ``Problem``, whose construction
    estimates the recording's f0): not part of the spec's value, so equal specs compare equal whatever
    either has built, and a copy or a pickle starts empty."""

    __slots__ = ("problem",)

    def __init__(self) -> None:
        self.problem = None

    def __eq__(self, other) -> bool:
        return isinstance(other, _Derived)

    __hash__ = None

    def __reduce__(self):
        return _Derived, ()

    def __deepcopy__(self, memo) -> _Derived:
        return _Derived()


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class GAWSpec(_Strict):
    """An observed glottal area waveform."""

    areas: list[FiniteFloat] = Field(
        min_length=4,
        max_length=MAX_FRAMES,
        description="glottal area per frame, mm^2, finite; negative values only "
        "within the recording's noise of zero (noise around a closed "
        "glottis, kept as measured)",
    )
    fps: FiniteFloat = Field(gt=0, le=1e6, description="camera frame rate, frames/s")
    units: Literal["mm2"] = "mm2"

    @field_validator("areas")
    @classmethod
    def _negative_only_as_noise(cls, v: list[float]) -> list[float]:
        from vfcore.gawio import check_negative

        why = check_negative(v)
        if why is not None:
            raise ValueError(why)
        return v

    @model_validator(mode="after")
    def _two_cycles(self) -> GAWSpec:
        from vfcore.inference.problem import validate_observation

        try:
            validate_observation(self.areas, self.fps)  # NaN/inf, constant, < 2 cycles
        except ValueError as exc:
            raise ValueError(f"gaw.areas: {exc}") from None
        return self


class ISSettings(_Strict):
    """Importance sampling from the prior."""

    kind: Literal["is"] = "is"
    n_samples: int = Field(ge=1, le=MAX_SIMULATIONS, description="number of prior draws (= simulations)")


class ScreenSettings(_Strict):
    """The cheap model of delayed-acceptance moves: the job's model on another mesh and time step."""

    mesh: Literal["coarse", "medium", "fine"] = Field(default="coarse", description="mesh of the screening model")
    dt: FiniteFloat = Field(default=1e-4, gt=0, le=1e-3, description="time step of the screening model, s")


class SMCSettings(_Strict):
    """Adaptive sequential Monte Carlo (tempered), run generation by generation."""

    kind: Literal["smc"] = "smc"
    n_particles: int = Field(ge=10, le=MAX_SIMULATIONS)
    max_generations: int = Field(default=50, ge=1, le=MAX_SMC_GENERATIONS)
    ess_fraction: FiniteFloat = Field(default=0.5, gt=0, lt=1, description="target relative ESS per tempering step")
    min_moves: int = Field(default=2, ge=1, le=50, description="fewest Metropolis moves per generation")
    max_moves: int = Field(default=8, ge=1, le=50, description="most Metropolis moves per generation")
    runs: int = Field(
        default=1,
        ge=1,
        le=MAX_SMC_RUNS,
        description="independent runs (own seeds), pooled: runs whose best particle lies more than 3 "
        "nats of log-likelihood below the best run's left out, the rest sharing the "
        "posterior equally (a single run of a rugged likelihood can settle in a basin of "
        "negligible mass); cost x runs",
    )
    screen: ScreenSettings | None = Field(
        default=None,
        description="delayed acceptance (Christen & Fox 2005): each proposal is first scored by this "
        "cheaper model and only the survivors are simulated with the job's model; the "
        "posterior stays the job's model's",
    )

    @model_validator(mode="after")
    def _moves(self) -> SMCSettings:
        if self.min_moves > self.max_moves:
            raise ValueError(f"sampler.min_moves ({self.min_moves}) must be <= max_moves ({self.max_moves})")
        return self

    def sampler_options(self) -> dict:
        return {
            "ess_fraction": self.ess_fraction,
            "max_generations": self.max_generations,
            "min_moves": self.min_moves,
            "max_moves": self.max_moves,
        }


SamplerSettings = Annotated[ISSettings | SMCSettings, Field(discriminator="kind")]


class JobSpec(_Strict):
    """Everything that defines one inference job."""

    version: Literal[1] = SCHEMA_VERSION
    model: str = Field(
        default="fe",
        description='"fe": the vfcore finite-element model; or another registered model '
        "(worker.models; a test double is accepted only when the service enables it)",
    )
    gaw: GAWSpec
    priors: dict[str, tuple[FiniteFloat, FiniteFloat]] | None = Field(
        default=None,
        description="{name: [lo, hi]} in paper units; omitted names keep the default (Table 2) bounds unless fixed",
    )
    fixed: dict[str, FiniteFloat] = Field(default_factory=dict, description="{name: value}, paper units")
    prior_set: Literal["paper", "human"] = Field(
        default="paper",
        description='the default bounds of parameters not in "priors": "paper" (Table 2, a '
        'silicone fold) or "human" (human tissue; docs/inference.md, "Prior sets")',
    )
    sampler: SamplerSettings
    mesh: Literal["coarse", "medium", "fine"] = "medium"
    dt: FiniteFloat = Field(default=5e-5, gt=0, le=1e-3, description="time step, s")
    contact: Literal[CONTACTS] = Field(
        default="projection",
        description="midline contact law: 'projection' (the paper's rigid midline, inelastic "
        "impact) or 'layer' (a compliant layer with the cover's modulus and "
        "viscosity; docs/model.md, 'Contact')",
    )
    contact_layer_mm: FiniteFloat = Field(
        default=0.1,
        gt=CONTACT_LAYER_MM[0],
        lt=CONTACT_LAYER_MM[1],
        description="contact layer thickness, mm (contact 'layer')",
    )
    duration: FiniteFloat = Field(default=0.55, gt=0, le=5.0, description="simulated time, s")
    discard: FiniteFloat = Field(default=0.25, ge=0, le=5.0, description="initial transient discarded, s")
    sigma_e: FiniteFloat = Field(gt=0, le=1e6, description="observation noise sd, mm^2")
    noise: Literal["fixed", "marginal"] = Field(
        default="fixed",
        description="'fixed': the likelihood uses sigma_e (paper, Eq. 15); 'marginal': the noise sd "
        "is unknown, log-uniform on sigma_bounds, and integrated out (docs/inference.md)",
    )
    sigma_bounds: tuple[FiniteFloat, FiniteFloat] = Field(
        default=(0.01, 100.0), description="[lo, hi] of the noise sd's log-uniform prior, mm^2 (noise='marginal')"
    )
    measurements: dict[str, tuple[FiniteFloat, FiniteFloat]] = Field(
        default_factory=dict,
        description="{name: [mean, sd]} in paper units: independent Gaussian measurements of "
        "estimated parameters (e.g. a measured p_sub), added to the likelihood; "
        "they anchor the common scale a GAW cannot determine (docs/inference.md)",
    )
    area_scale: tuple[FiniteFloat, FiniteFloat] | None = Field(
        default=None,
        description="[k_lo, k_hi]: the recorded areas are k times the true areas with k unknown (a video "
        "without spatial calibration; k = (true px/mm / assumed px/mm)^2), uniform on "
        "[k_lo, k_hi] and integrated out of the likelihood; null: calibrated areas "
        "(docs/inference.md, 'Unknown area scale')",
    )
    seed: int = Field(ge=0, lt=2**63)
    chunk_size: int | None = Field(
        default=None, ge=1, le=10_000, description="simulations per worker task (default: sized to run for seconds)"
    )
    model_options: dict[str, Any] | None = Field(
        default=None, description="options of a registered model that takes some (its defaults when omitted)"
    )
    force_reach: bool = Field(
        default=False,
        description="fit even when the recording lies outside the model's reach (its GAW measures "
        'beyond every prior-predictive draw; docs/inference.md, "The model\'s reach"): '
        "the job is accepted with a warning instead of a 422",
    )
    _derived: _Derived = PrivateAttr(default_factory=_Derived)

    @model_validator(mode="before")
    @classmethod
    def _stored_options_name(cls, data):
        # a stored schema-1 spec may name the model options after the one model that had some
        if isinstance(data, dict) and "toy" in data and "model_options" not in data:
            data = {**data, "model_options": data["toy"]}
            del data["toy"]
        return data

    @field_validator("model")
    @classmethod
    def _known_model(cls, v):
        from .models import model_named

        model_named(v)
        return v

    def _check_model_options(self) -> None:
        """Validate ``model_options`` against the model's options type and store them with defaults filled in."""
        from .models import model_named

        kind = model_named(self.model).options_type
        if kind is None:
            if self.model_options is not None:
                raise ValueError(f"model_options: options given but model {self.model!r} takes none")
            return
        try:
            opts = kind.model_validate(self.model_options or {})
        except ValidationError as exc:
            err = exc.errors()[0]
            raise ValueError(f"model_options.{'.'.join(map(str, err['loc']))}: {err['msg']}") from None
        object.__setattr__(self, "model_options", opts.model_dump())

    @field_validator("sigma_bounds")
    @classmethod
    def _check_sigma_bounds(cls, v):
        lo, hi = v
        if not 0 < lo < hi:
            raise ValueError(f"sigma_bounds must satisfy 0 < lo < hi, got [{lo}, {hi}]")
        return v

    @field_validator("area_scale")
    @classmethod
    def _check_area_scale(cls, v):
        from vfcore.inference.problem import validate_area_scale

        return validate_area_scale(v)

    @field_validator("priors")
    @classmethod
    def _check_priors(cls, v):
        if v is None:
            return v
        for name, (lo, hi) in v.items():
            if name not in PARAM_NAMES:
                raise ValueError(f"unknown parameter {name!r}; known: {list(PARAM_NAMES)}")
            if not lo < hi:
                raise ValueError(f"prior for {name}: lo ({lo}) must be < hi ({hi})")
        return v

    @field_validator("measurements")
    @classmethod
    def _check_measurements(cls, v):
        from vfcore.inference.problem import validate_measurements

        validate_measurements(v)  # names and sds; against the prior in the model validator
        return v

    @field_validator("fixed")
    @classmethod
    def _check_fixed(cls, v):
        for name in v:
            if name not in PARAM_NAMES:
                raise ValueError(f"unknown parameter {name!r}; known: {list(PARAM_NAMES)}")
        return v

    @model_validator(mode="after")
    def _consistent(self) -> JobSpec:
        both = set(self.priors or {}) & set(self.fixed)
        if both:
            raise ValueError(f"fixed: parameter(s) {sorted(both)} both fixed and given a prior")
        if len(self.fixed) == len(PARAM_NAMES):
            raise ValueError("fixed: every parameter is fixed; nothing to infer")
        if self.discard >= self.duration:
            raise ValueError(f"discard ({self.discard}) must be < duration ({self.duration})")
        if self.gaw.fps * self.dt > 1.0:
            raise ValueError(f"dt: camera fps {self.gaw.fps} exceeds the simulation rate 1/dt={1 / self.dt:.0f}")
        if self.mesh not in MESHES:  # pragma: no cover - Literal already enforces it
            raise ValueError(f"mesh must be one of {MESHES}")
        self._check_model_options()
        try:
            prior = self.to_prior()
        except ValueError as exc:
            raise ValueError(f"priors/fixed: {exc}") from None
        from vfcore.inference.problem import validate_measurements

        try:
            validate_measurements(self.measurements, prior)
        except ValueError as exc:
            raise ValueError(f"measurements: {exc}") from None
        try:
            self._derived.problem = self._problem(prior)
        except ValueError as exc:
            raise ValueError(f"gaw/duration/discard: {exc}") from None
        return self

    # ------------------------------------------------------------------ derived quantities
    def __copy__(self) -> JobSpec:
        # model_copy(update=...) makes a spec with other fields: it must not keep this spec's Problem
        m = super().__copy__()
        m.__pydantic_private__["_derived"] = _Derived()
        return m

    @property
    def n_simulations(self) -> int:
        """Simulations of the first (IS: only) stage, known up front."""
        if isinstance(self.sampler, ISSettings):
            return self.sampler.n_samples
        return self.sampler.n_particles

    def to_json(self) -> str:
        return self.model_dump_json()

    @classmethod
    def from_json(cls, s: str | bytes) -> JobSpec:
        return cls.model_validate_json(s)

    def sim_config(self):
        from vfcore.config import SimConfig

        return SimConfig(
            mesh=self.mesh,
            dt=self.dt,
            duration=self.duration,
            discard=self.discard,
            fps=self.gaw.fps,
            contact=self.contact,
            contact_layer_mm=self.contact_layer_mm,
        )

    def observed(self) -> np.ndarray:
        return np.asarray(self.gaw.areas, dtype=float)

    def to_prior(self):
        """The ``vfcore.inference`` Prior: the prior set's bounds, overridden by ``priors``, minus ``fixed``."""
        from vfcore.inference.prior import PRIOR_SETS, Prior

        bounds = {k: tuple(v) for k, v in PRIOR_SETS[self.prior_set].items()}
        bounds.update({k: (float(lo), float(hi)) for k, (lo, hi) in (self.priors or {}).items()})
        for k in self.fixed:
            bounds.pop(k, None)
        return Prior(bounds=bounds, fixed={k: float(v) for k, v in self.fixed.items()})

    def _problem(self, prior):
        from vfcore.inference.problem import Problem

        return Problem(
            obs_gaw=self.observed(),
            fps=float(self.gaw.fps),
            prior=prior,
            sigma_e=float(self.sigma_e),
            config=self.sim_config(),
            noise=self.noise,
            sigma_bounds=tuple(float(b) for b in self.sigma_bounds),
            measurements={k: (float(m), float(sd)) for k, (m, sd) in self.measurements.items()},
            area_scale=self.area_scale,
        )

    def to_problem(self):
        """The ``vfcore.inference.Problem`` this job solves (every registered model is scored against it): the
        one built when the spec was validated, so every stage of a run that holds this spec shares it."""
        if self._derived.problem is None:
            self._derived.problem = self._problem(self.to_prior())
        return self._derived.problem

    def reach(self):
        """The reach check of this job's recording (``vfcore.inference.reach.reach_for``): a
        :class:`~vfcore.inference.reach.ReachVerdict`, "unchecked" where no ensemble matches the configuration
        and prior (none is built here: that takes minutes) and for a model other than "fe", which is not
        the model the ensembles describe."""
        from vfcore.inference.reach import ReachVerdict, reach_for

        if self.model != "fe":
            return ReachVerdict("unchecked", f"the model's reach is not checked for model {self.model!r}", exact=False)
        return reach_for(
            self.observed(), float(self.gaw.fps), self.sim_config(), self.to_prior(), area_scale=self.area_scale
        )
