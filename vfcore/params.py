"""Model parameters at the edge (paper units) and their SI conversion.

Units at the edge follow Hadwin et al. (2019), Table 2/3: E_body kPa, E_cover Pa,
E_lig kPa, p_sub Pa, rho kg/m^3, eta Poise, x0 mm. Everything inside vfcore is SI.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

import numpy as np

#: Estimated parameters, in the order used for arrays everywhere in vfinfer.
PARAM_NAMES: tuple[str, ...] = ("E_body", "E_cover", "E_lig", "p_sub", "rho", "eta", "x0")

#: Units of each parameter at the edge (input/output).
PARAM_UNITS: dict[str, str] = {
    "E_body": "kPa",
    "E_cover": "Pa",
    "E_lig": "kPa",
    "p_sub": "Pa",
    "rho": "kg/m^3",
    "eta": "Poise",
    "x0": "mm",
}

#: Multiply an edge value by this factor to get SI (Pa, Pa, Pa, Pa, kg/m^3, Pa s, m).
TO_SI: dict[str, float] = {
    "E_body": 1e3,
    "E_cover": 1.0,
    "E_lig": 1e3,
    "p_sub": 1.0,
    "rho": 1.0,
    "eta": 0.1,
    "x0": 1e-3,
}

#: Fold width (medial-lateral extent) of the undeformed M5 section, mm.  x0 = this means
#: no medial compression.
FOLD_WIDTH_MM = 8.4


@dataclass(frozen=True)
class Params:
    """One parameter vector in paper units (see module docstring)."""

    E_body: float
    E_cover: float
    E_lig: float
    p_sub: float
    rho: float
    eta: float
    x0: float = FOLD_WIDTH_MM

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(float(v)):
                raise ValueError(f"parameter {f.name} must be a finite number, got {v!r}")
            object.__setattr__(self, f.name, float(v))
        for name in ("E_body", "E_cover", "E_lig", "rho", "eta"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"parameter {name} must be > 0 ({PARAM_UNITS[name]}), got {getattr(self, name)}")
        if self.p_sub < 0.0:
            raise ValueError(f"parameter p_sub must be >= 0 Pa, got {self.p_sub}")
        if not (0.0 < self.x0 <= FOLD_WIDTH_MM):
            raise ValueError(
                f"parameter x0 must lie in (0, {FOLD_WIDTH_MM}] mm (8.4 = no medial compression), got {self.x0}"
            )

    @classmethod
    def from_dict(cls, d: dict) -> Params:
        unknown = set(d) - set(PARAM_NAMES)
        if unknown:
            raise ValueError(f"unknown parameter name(s): {sorted(unknown)}; known: {list(PARAM_NAMES)}")
        return cls(**d)

    @classmethod
    def from_array(cls, a) -> Params:
        a = np.asarray(a, dtype=float)
        if a.shape != (len(PARAM_NAMES),):
            raise ValueError(f"parameter array must have shape ({len(PARAM_NAMES)},), got {a.shape}")
        return cls(*a.tolist())

    def as_dict(self) -> dict[str, float]:
        return asdict(self)

    def as_array(self) -> np.ndarray:
        return np.array([getattr(self, n) for n in PARAM_NAMES])

    def si(self) -> dict[str, float]:
        """Parameters in SI units (Pa, kg/m^3, Pa s, m)."""
        return {n: getattr(self, n) * TO_SI[n] for n in PARAM_NAMES}

    def replace(self, **kw) -> Params:
        d = self.as_dict()
        d.update(kw)
        return Params.from_dict(d)


#: Hadwin et al. (2019), Table 3: the experimentally measured silicone values.
TABLE3 = Params(E_body=12.15, E_cover=636.2, E_lig=1.808, p_sub=989.9, rho=1051.0, eta=3.079, x0=8.4)
