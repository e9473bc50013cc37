"""Simulation configuration (numerics and observation), SI units except where named."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

MESHES = (
    "coarse",
    "medium",
    "fine",
    "xfine",
    "xxfine",
)  # ~172, ~205, ~263, ~1050, ~4190 triangles; "medium" is the paper's default
ELEMENTS = ("p1", "anp")  # as vfcore.fem.assemble.ELEMENTS (kept import-free here)
CONTACTS = ("projection", "layer")
FLOWS = ("continuous", "paper")  # the flow load: continuous between nodes, or the paper's node-wise rule
CONTACT_LAYER_MM = (0.0, 1.0)  # open bounds of the contact layer's thickness, mm (SimConfig, job spec, command line)
#: settings that change how a simulation is run or kept, not the waveform it gives (early_stop changes it by
#: less than its stop tolerances): left out when two models are compared
NOT_MODEL = ("keep_trajectories", "early_stop")


def contact_label(contact, layer_mm=None) -> str:
    """How reports name a contact law: ``"projection"``, or ``"layer 0.1 mm"`` with the layer's thickness."""
    if contact != "layer":
        return str(contact)
    return f"layer {layer_mm:g} mm" if isinstance(layer_mm, (int, float)) else "layer"


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
    closure_gap_mm : small-gap regularisation of the flow load, mm (0 = the paper's hard switch
        between open-glottis Bernoulli and closed-glottis pressures; default 0.02). Below this minimum half
        gap the two distributions are blended smoothly; see :ref:`model-closure-regularisation-a-deliberate-deviation`.

    Model extensions (off by default; :ref:`model-extensions`):

    epithelium_E_kpa : Young's modulus of a thin epithelium membrane along the free surface, kPa
        (0 = off). Each free-surface edge of reference length l_e becomes a 2-node bar of axial
        stiffness E' h / l_e per unit fold length, E' = E / (1 - nu^2) (plane strain, nu = ``nu``).
    epithelium_h_mm : epithelium thickness h, mm, in (0, 1).
    epithelium_profile : per free-surface edge stiffness multipliers (>= 0), inferior -> superior;
        () = uniform. Its length must equal the number of surface edges of the mesh
        (``len(mesh.surface) - 1``); checked in :func:`vfcore.forward.simulate`.
    subglottal_modes : subglottal input-impedance modes ((f_hz, zeta, Z_peak), ...): f_hz > 0 Hz,
        zeta in (0, 1], Z_peak > 0 Pa s/m^3. The glottal inlet pressure is p_sub - sum_k p_k with
        p_k'' + 2 zeta w p_k' + w^2 p_k = 2 zeta w Z_peak dQ/dt (w = 2 pi f_hz). () = off.
    element : displacement element, one of ``ELEMENTS``: "p1" (the paper's linear triangle) or
        "anp" (P1 with nodally averaged volumetric part, locking-free as nu -> 1/2; :ref:`model-numerics-locking-and-mesh-convergence`,
        "Locking and mesh convergence").
    contact : midline contact law, one of ``CONTACTS`` (:ref:`model-contact`): "projection" (the
        paper's rigid midline: exact multipliers and an inelastic impact, whose peak pressures depend on
        the time step and the mesh) or "layer" (a compliant Kelvin-Voigt contact layer of thickness
        ``contact_layer_mm`` with the cover's modulus E_cover and viscosity eta: pressure
        E_cover * overlap / h + eta * overlap rate / h, no adhesion).
    contact_layer_mm : thickness h of the contact layer, mm, in (0, 1) (used by ``contact="layer"``).
    flow : the flow load, one of ``FLOWS`` (:ref:`continuous-model`): "continuous" (separation
        at the interpolated crossing of ``sep_ratio * g_min``, closure at the interpolated zero of the gap, the
        pressure integrated over each edge, near-closure suction and upstream pockets faded over
        ``closure_gap_mm``: the load is a continuous function of the surface) or "paper" (the paper's node-wise
        rule: separation at the first node past the crossing, p_sub up to the first closed node, node values
        lumped by halves onto the edges; with ``closure_gap_mm > 0`` blended into the closed distribution near
        closure).
    early_stop : stop a simulation whose response has settled (no oscillation to come) and repeat its
        last state to the end, instead of integrating the rest
        (:ref:`model-numerics-stopping-settled-simulations`): the GAW differs by less than the stop tolerances,
        the cost drops.
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
    closure_gap_mm: float = 0.02
    epithelium_E_kpa: float = 0.0
    epithelium_h_mm: float = 0.05
    epithelium_profile: tuple[float, ...] = ()
    subglottal_modes: tuple[tuple[float, float, float], ...] = ()
    element: str = "p1"
    contact: str = "projection"
    contact_layer_mm: float = 0.1
    flow: str = "paper"
    early_stop: bool = True

    def __post_init__(self) -> None:
        if self.mesh not in MESHES:
            raise ValueError(f"mesh must be one of {MESHES}, got {self.mesh!r}")
        if self.element not in ELEMENTS:
            raise ValueError(f"config element must be one of {ELEMENTS}, got {self.element!r}")
        if self.contact not in CONTACTS:
            raise ValueError(f"config contact must be one of {CONTACTS}, got {self.contact!r}")
        if self.flow not in FLOWS:
            raise ValueError(f"config flow must be one of {FLOWS}, got {self.flow!r}")
        if not isinstance(self.early_stop, bool):
            raise ValueError(f"config early_stop must be True or False, got {self.early_stop!r}")
        hl = self.contact_layer_mm
        lo, hi = CONTACT_LAYER_MM
        if not (isinstance(hl, (int, float)) and math.isfinite(hl) and lo < hl < hi):
            raise ValueError(f"config contact_layer_mm must lie in ({lo:g}, {hi:g}) mm, got {hl!r}")
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
        if not (math.isfinite(self.closure_gap_mm) and 0.0 <= self.closure_gap_mm < 1.0):
            raise ValueError(f"config closure_gap_mm must lie in [0, 1) mm, got {self.closure_gap_mm!r}")
        if not math.isfinite(self.p_sup):
            raise ValueError(f"config p_sup must be finite, got {self.p_sup!r}")
        if self.fps * self.dt > 1.0:
            raise ValueError(f"config fps={self.fps} exceeds the simulation rate 1/dt={1 / self.dt:.0f}")
        self._check_extensions()

    def _check_extensions(self) -> None:
        E, hh = self.epithelium_E_kpa, self.epithelium_h_mm
        if not (isinstance(E, (int, float)) and math.isfinite(E) and E >= 0):
            raise ValueError(f"config epithelium_E_kpa must be a finite number >= 0 (kPa), got {E!r}")
        if not (isinstance(hh, (int, float)) and math.isfinite(hh) and 0.0 < hh < 1.0):
            raise ValueError(f"config epithelium_h_mm must lie in (0, 1) mm, got {hh!r}")
        try:
            prof = tuple(float(x) for x in self.epithelium_profile)
        except (TypeError, ValueError):
            raise ValueError(
                f"config epithelium_profile must be a sequence of numbers, got {self.epithelium_profile!r}"
            ) from None
        if not all(math.isfinite(x) and x >= 0 for x in prof):
            raise ValueError(f"config epithelium_profile multipliers must be finite and >= 0, got {prof!r}")
        object.__setattr__(self, "epithelium_profile", prof)
        if prof:
            from .mesh import load_mesh

            n_edges = len(load_mesh(self.mesh).surface) - 1
            if len(prof) != n_edges:
                raise ValueError(
                    f"config epithelium_profile must have one multiplier per free-surface edge of mesh "
                    f"{self.mesh!r}: expected length {n_edges}, got {len(prof)}"
                )
        modes = []
        try:
            raw = tuple(self.subglottal_modes)
        except TypeError:
            raise ValueError(
                f"config subglottal_modes must be a sequence of (f_hz, zeta, Z_peak), got {self.subglottal_modes!r}"
            ) from None
        for k, md in enumerate(raw):
            try:
                f, z, Zp = (float(x) for x in md)
            except (TypeError, ValueError):
                raise ValueError(f"config subglottal_modes[{k}] must be (f_hz, zeta, Z_peak), got {md!r}") from None
            if not (math.isfinite(f) and f > 0):
                raise ValueError(f"config subglottal_modes[{k}] f_hz must be finite and > 0, got {f!r}")
            if not (math.isfinite(f) and f < 0.5 / self.dt):
                raise ValueError(
                    f"config subglottal_modes[{k}] f_hz={f} must lie below the Nyquist rate "
                    f"1/(2 dt) = {0.5 / self.dt:.0f} Hz"
                )
            if not (math.isfinite(z) and 0.0 < z <= 1.0):
                raise ValueError(f"config subglottal_modes[{k}] zeta must lie in (0, 1], got {z!r}")
            if not (math.isfinite(Zp) and Zp > 0):
                raise ValueError(f"config subglottal_modes[{k}] Z_peak must be finite and > 0 (Pa s/m^3), got {Zp!r}")
            modes.append((f, z, Zp))
        object.__setattr__(self, "subglottal_modes", tuple(modes))

    @property
    def has_epithelium(self) -> bool:
        return self.epithelium_E_kpa > 0

    @property
    def has_subglottal(self) -> bool:
        return len(self.subglottal_modes) > 0

    @property
    def has_extensions(self) -> bool:
        """True when any forward-model extension (epithelium, subglottal coupling) is on."""
        return self.has_epithelium or self.has_subglottal

    def as_dict(self) -> dict:
        return asdict(self)

    def replace(self, **kw) -> "SimConfig":
        d = self.as_dict()
        d.update(kw)
        return SimConfig(**d)

    def as_record(self) -> dict:
        """:meth:`as_dict` as JSON gives it back (tuples as lists): what a stored record such as
        ``Posterior.model`` holds, and what :meth:`differences` compares."""
        import json

        return json.loads(json.dumps(self.as_dict()))

    def differences(self, recorded: dict) -> dict[str, tuple]:
        """The model settings in which ``recorded`` (an :meth:`as_record`, e.g. ``Posterior.model``) differs from
        this config: ``{name: (recorded value, this value)}``. Settings ``recorded`` does not carry, and those in
        ``NOT_MODEL``, are not compared; the layer thickness only when both use the layer."""
        out = {}
        for k, v in self.as_record().items():
            if k in NOT_MODEL or k not in recorded:
                continue
            if k == "contact_layer_mm" and not (self.contact == recorded.get("contact") == "layer"):
                continue
            if recorded[k] != v:
                out[k] = (recorded[k], v)
        return out
