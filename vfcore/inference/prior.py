"""Independent uniform priors on the model parameters (Hadwin et al. 2019, Table 2).

Bounds are in paper units (kPa, Pa, kPa, Pa, kg/m^3, Poise, mm; see ``vfcore.params``).
Any parameter may be *fixed* instead of estimated; parameters that are neither
estimated nor fixed take the measured silicone values of Table 3 (``vfcore.params.TABLE3``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from ..params import FOLD_WIDTH_MM, PARAM_NAMES, PARAM_UNITS, TABLE3, Params

#: Hadwin et al. (2019), Table 2: bounds of the uniform priors (paper units).
TABLE2_BOUNDS: dict[str, tuple[float, float]] = {
    "E_body": (9.0, 15.0),  # kPa
    "E_cover": (250.0, 950.0),  # Pa
    "E_lig": (0.5, 3.0),  # kPa
    "p_sub": (400.0, 1800.0),  # Pa
    "rho": (950.0, 1200.0),  # kg/m^3
    "eta": (1.0, 7.0),  # Poise
    "x0": (7.4, 8.4),  # mm
}

#: Priors for human vocal folds (:ref:`inference-reach-prior-sets`). The 2D section has no longitudinal tension, the
#: main control of f0 in a human larynx, so its in-plane moduli are effective ones that stand for it too. Cover:
#: the lamina propria's transverse Young's modulus, about 1 kPa at low strain and 10-15 times that at high strain
#: (Alipour & Vigmostad 2012, J Voice 26(6):816.e21), here up to 10 kPa, softer than the body; body: the range
#: the prior predictive needs to span human f0 (85-255 Hz) on the M5 section; ligament between them; p_sub:
#: phonation from threshold to loud voice, 0.5-2.5 kPa (Titze 1994, Principles of Voice Production); density of
#: soft tissue; viscosity as in Table 2; x0: at most 0.4 mm of medial compression, since with tissue this stiff
#: more compression holds the glottis shut against any phonatory pressure (measured: no draw with x0 < 8.1 mm
#: phonated out of 2,000 from a first, wider box with Table 2's x0 range).
HUMAN_BOUNDS: dict[str, tuple[float, float]] = {
    "E_body": (10.0, 200.0),  # kPa
    "E_cover": (1000.0, 10000.0),  # Pa
    "E_lig": (5.0, 40.0),  # kPa
    "p_sub": (500.0, 2500.0),  # Pa
    "rho": (1000.0, 1100.0),  # kg/m^3
    "eta": (1.0, 7.0),  # Poise
    "x0": (8.0, 8.4),  # mm
}

#: Named prior sets (``Prior.default(prior_set=...)``, ``vfinfer infer --prior-set``).
PRIOR_SETS: dict[str, dict[str, tuple[float, float]]] = {"paper": TABLE2_BOUNDS, "human": HUMAN_BOUNDS}

_POSITIVE = ("E_body", "E_cover", "E_lig", "rho", "eta")


def _check_name(name: str) -> None:
    if name not in PARAM_NAMES:
        raise ValueError(f"unknown parameter name {name!r}; known: {list(PARAM_NAMES)}")


def _check_value_domain(name: str, v: float, what: str) -> None:
    """Raise ValueError if ``v`` lies outside the physical domain of ``name``."""
    if not math.isfinite(v):
        raise ValueError(f"{what} of {name} must be finite, got {v!r}")
    if name in _POSITIVE and v <= 0.0:
        raise ValueError(f"{what} of {name} must be > 0 {PARAM_UNITS[name]}, got {v}")
    if name == "p_sub" and v < 0.0:
        raise ValueError(f"{what} of p_sub must be >= 0 Pa, got {v}")
    if name == "x0" and not (0.0 < v <= FOLD_WIDTH_MM):
        raise ValueError(f"{what} of x0 must lie in (0, {FOLD_WIDTH_MM}] mm, got {v}")


@dataclass(frozen=True, eq=False)
class Prior:
    """Independent uniform prior over the estimated parameters.

    Parameters
    ----------
    bounds : ``{name: (lo, hi)}`` in paper units for every *estimated* parameter.
    fixed : ``{name: value}`` for parameters held fixed (must not also be in ``bounds``).

    Arrays (``sample``, ``logpdf``, ``lo``, ``hi``) list the estimated parameters in
    ``PARAM_NAMES`` order, which is ``self.names``.
    """

    bounds: Mapping[str, tuple[float, float]]
    fixed: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.bounds, Mapping) or not isinstance(self.fixed, Mapping):
            raise ValueError("Prior bounds and fixed must be mappings {name: ...}")
        bounds: dict[str, tuple[float, float]] = {}
        for name, b in self.bounds.items():
            _check_name(name)
            try:
                lo, hi = (float(b[0]), float(b[1]))
                if len(b) != 2:
                    raise TypeError
            except (TypeError, ValueError, IndexError):
                raise ValueError(f"bounds of {name} must be a pair (lo, hi), got {b!r}") from None
            _check_value_domain(name, lo, "lower bound")
            _check_value_domain(name, hi, "upper bound")
            if not lo < hi:
                raise ValueError(f"bounds of {name} must satisfy lo < hi, got lo={lo}, hi={hi}")
            bounds[name] = (lo, hi)
        fixed: dict[str, float] = {}
        for name, v in self.fixed.items():
            _check_name(name)
            if name in bounds:
                raise ValueError(f"parameter {name} is both estimated (in bounds) and fixed")
            try:
                fv = float(v)
            except (TypeError, ValueError):
                raise ValueError(f"fixed value of {name} must be a number, got {v!r}") from None
            _check_value_domain(name, fv, "fixed value")
            fixed[name] = fv
        if not bounds:
            raise ValueError("a Prior needs at least one estimated parameter")
        # canonical order
        object.__setattr__(self, "bounds", {n: bounds[n] for n in PARAM_NAMES if n in bounds})
        object.__setattr__(self, "fixed", {n: fixed[n] for n in PARAM_NAMES if n in fixed})

    # ------------------------------------------------------------------ constructors
    @classmethod
    def default(cls, fixed: Mapping[str, float] | None = None, prior_set: str = "paper") -> Prior:
        """The priors of ``prior_set`` (``PRIOR_SETS``: "paper" = Table 2, "human"); names in ``fixed`` are
        held at the given values instead."""
        if prior_set not in PRIOR_SETS:
            raise ValueError(f"unknown prior set {prior_set!r}; known: {sorted(PRIOR_SETS)}")
        fixed = dict(fixed or {})
        for name in fixed:
            _check_name(name)
        return cls({n: b for n, b in PRIOR_SETS[prior_set].items() if n not in fixed}, fixed)

    # ------------------------------------------------------------------ properties
    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.bounds)

    @property
    def ndim(self) -> int:
        return len(self.bounds)

    @property
    def lo(self) -> np.ndarray:
        return np.array([b[0] for b in self.bounds.values()])

    @property
    def hi(self) -> np.ndarray:
        return np.array([b[1] for b in self.bounds.values()])

    @property
    def width(self) -> np.ndarray:
        return self.hi - self.lo

    # ------------------------------------------------------------------ density
    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` independent draws, shape (n, d)."""
        u = rng.random((int(n), self.ndim))
        return self.lo + u * self.width

    def contains(self, thetas) -> np.ndarray:
        t = np.atleast_2d(np.asarray(thetas, dtype=float))
        return np.all((t >= self.lo) & (t <= self.hi), axis=1)

    def logpdf(self, thetas) -> np.ndarray:
        """Log density, shape (k,) (``-inf`` outside the box)."""
        t = np.atleast_2d(np.asarray(thetas, dtype=float))
        if t.shape[1] != self.ndim:
            raise ValueError(f"thetas must have {self.ndim} columns ({self.names}), got shape {t.shape}")
        out = np.full(t.shape[0], -float(np.sum(np.log(self.width))))
        out[~self.contains(t)] = -np.inf
        return out

    # ------------------------------------------------------------------ to model
    def full_array(self, thetas) -> np.ndarray:
        """All seven parameters (k, 7) in ``PARAM_NAMES`` order for estimated rows ``thetas`` (k, d)."""
        t = np.atleast_2d(np.asarray(thetas, dtype=float))
        if t.shape[1] != self.ndim:
            raise ValueError(f"thetas must have {self.ndim} columns ({self.names}), got shape {t.shape}")
        base = TABLE3.as_array()
        out = np.tile(base, (t.shape[0], 1))
        for j, n in enumerate(PARAM_NAMES):
            if n in self.fixed:
                out[:, j] = self.fixed[n]
        for i, n in enumerate(self.names):
            out[:, PARAM_NAMES.index(n)] = t[:, i]
        return out

    def to_params(self, theta) -> Params:
        """``Params`` for one estimated vector ``theta`` (d,), merged with fixed / Table 3 values."""
        theta = np.asarray(theta, dtype=float)
        if theta.shape != (self.ndim,):
            raise ValueError(f"theta must have shape ({self.ndim},), got {theta.shape}")
        return Params.from_array(self.full_array(theta[None, :])[0])

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict:
        return {"bounds": {n: [lo, hi] for n, (lo, hi) in self.bounds.items()}, "fixed": dict(self.fixed)}

    @classmethod
    def from_dict(cls, d: Mapping) -> Prior:
        if not isinstance(d, Mapping) or "bounds" not in d:
            raise ValueError("Prior.from_dict needs a mapping with a 'bounds' entry")
        unknown = set(d) - {"bounds", "fixed"}
        if unknown:
            raise ValueError(f"unknown Prior field(s): {sorted(unknown)}")
        return cls({n: tuple(b) for n, b in d["bounds"].items()}, dict(d.get("fixed", {})))

    def __eq__(self, other) -> bool:
        return isinstance(other, Prior) and self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash((tuple(self.bounds.items()), tuple(self.fixed.items())))

    def __repr__(self) -> str:
        b = ", ".join(f"{n}=[{lo:g}, {hi:g}]" for n, (lo, hi) in self.bounds.items())
        f = ", ".join(f"{n}={v:g}" for n, v in self.fixed.items())
        return f"Prior({b}" + (f"; fixed {f})" if f else ")")
