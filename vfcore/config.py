"""Simulation configuration (numerics and observation), SI units except where named."""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

MESHES = ("coarse", "medium", "fine")  # ~172, ~205, ~263 triangles; "medium" is the paper's default
ELEMENTS = ("p1", "anp")  # as vfcore.fem.assemble.ELEMENTS (kept import-free here)


@dataclass(frozen=True)
class SimConfig:
    """Numerical and observation settings of one forward simulation.

    Attributes
    ----------
    mesh : one of ``MESHES``.
    dt : time step, s (paper: 5e-5; 2.5e-5 and 1e-4 supported).
    duration : simulated time, s (paper: 0.55).
    discard : initial transient thrown away, s (paper: 0.25).
    fps : camera frame rate the GAW is downsampled to, frames/s.
    nu : Poisson ratio, in (-1, 0.5).
    sep_ratio : flow separates where the area first exceeds ``sep_ratio * A_min``.
    p_sup : supraglottal pressure, Pa.
    length_mm : fold length (anterior-posterior), mm; area = length * width.
    rho_inf : high-frequency spectral radius of the time integrator; 1 = Newmark average
        acceleration (the paper), < 1 = generalised-alpha with numerical dissipation.
    half_gap_mm : prephonatory half gap, mm: the midline (contact plane) lies at x0 + half_gap_mm.
    keep_trajectories : also return nodal displacements at the camera rate.
    element : displacement element, one of ``ELEMENTS``: "p1" (the paper's linear triangle) or
        "anp" (P1 with nodally averaged volumetric part, locking-free as nu -> 1/2; docs/model.md,
        "Locking and mesh convergence").
    """

    mesh: str = "medium"
    dt: float = 5e-5
    duration: float = 0.55
    discard: float = 0.25
    fps: float = 2000.0
    nu: float = 0.4995
    sep_ratio: float = 1.3
    p_sup: float = 0.0
    length_mm: float = 17.0
    half_gap_mm: float = 0.05
    rho_inf: float = 1.0
    keep_trajectories: bool = False
    element: str = "p1"

    def __post_init__(self) -> None:
        if self.mesh not in MESHES:
            raise ValueError(f"mesh must be one of {MESHES}, got {self.mesh!r}")
        if self.element not in ELEMENTS:
            raise ValueError(f"config element must be one of {ELEMENTS}, got {self.element!r}")
        for name in ("dt", "duration", "fps", "length_mm", "sep_ratio"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"config {name} must be a finite number > 0, got {v!r}")
        if not (math.isfinite(self.discard) and 0 <= self.discard < self.duration):
            raise ValueError(f"config discard must be in [0, duration), got {self.discard!r}")
        if not (math.isfinite(self.nu) and -1.0 < self.nu < 0.5):
            raise ValueError(f"config nu (Poisson ratio) must lie in (-1, 0.5), got {self.nu!r}")
        if self.sep_ratio < 1.0:
            raise ValueError(f"config sep_ratio must be >= 1, got {self.sep_ratio!r}")
        if not (math.isfinite(self.rho_inf) and 0.0 <= self.rho_inf <= 1.0):
            raise ValueError(f"config rho_inf must lie in [0, 1], got {self.rho_inf!r}")
        if not (math.isfinite(self.half_gap_mm) and self.half_gap_mm >= 0):
            raise ValueError(f"config half_gap_mm must be >= 0, got {self.half_gap_mm!r}")
        if not math.isfinite(self.p_sup):
            raise ValueError(f"config p_sup must be finite, got {self.p_sup!r}")
        if self.fps * self.dt > 1.0:
            raise ValueError(f"config fps={self.fps} exceeds the simulation rate 1/dt={1/self.dt:.0f}")

    def as_dict(self) -> dict:
        return asdict(self)

    def replace(self, **kw) -> "SimConfig":
        d = self.as_dict()
        d.update(kw)
        return SimConfig(**d)
