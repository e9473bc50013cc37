"""Catalogue of left-out physics: optional model extensions, their priors and GAW signatures.

Each :class:`Extension` has extra parameters with uniform physical priors (:class:`ExtParam`,
bounds and source), the GAW signature it explains (phases of :mod:`.locate` and measures of
:mod:`vfcore.measures`), and an ``apply(base, theta, fps=...)`` mapping a base simulation
(:class:`vfcore.result.SimResult` or a GAW array) to the extended observation.

Kinds:

- ``observation``: act on the simulated GAW only — leak area, camera scale error, exposure
  averaging, frame-rate mismatch, anterior–posterior zipper, left–right phase/amplitude
  asymmetry.
- ``forward``: a forward-model parameter, re-simulated — ``sep_ratio``, epithelium layer,
  subglottal resonator, left–right stiffness asymmetry (``SimConfig`` fields).
- ``structural``: an entry catalogued with ``implemented=False`` (``apply`` raises
  ``NotImplementedError``) so that the ranking can name what a signature would point to
  before it can be fitted; every entry of :data:`CATALOGUE` is implemented.

Sources and prior ranges are in ``:ref:`diagnose`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "ExtParam",
    "Extension",
    "CATALOGUE",
    "get",
    "implemented",
    "apply_leak",
    "apply_scale",
    "apply_exposure",
    "apply_frame_rate",
    "leak_flow",
    "leak_extra",
    "RHO_AIR",
    "SUB_LOG10_Z_OFF",
    "matching",
    "physics_of",
]

#: Air density, kg/m^3 (at 37 °C, saturated; Titze, Principles of Voice Production).
RHO_AIR = 1.14

#: Lower bound of the subglottal entry's log10 peak impedance (Pa s/m^3), taken as no coupling: a
#: resonance of 100 Pa s/m^3 carries ~0.03 Pa at phonatory flows, and on Table 3 (medium mesh) moves
#: the GAW by at most 0.002 mm^2, so the entry reaches the base model continuously and *is* it there.
SUB_LOG10_Z_OFF = 2.0


@dataclass(frozen=True)
class ExtParam:
    """One extra parameter: uniform prior ``[lo, hi]`` in ``unit``. ``null``: the value at which
    the extension is the base model; ``None`` where the prior holds no such value (a membrane's
    stiffness or a resonance frequency, which act only through a thickness or an impedance that has
    one). Used by the naming rule to tell a physics gain from a mode-finding gain (:ref:`diagnose`,
    section 3)."""

    name: str
    lo: float
    hi: float
    unit: str
    source: str
    null: float | None = None


@dataclass(frozen=True)
class Extension:
    name: str
    kind: str  # "observation" | "forward" | "structural"
    params: tuple[ExtParam, ...]
    phases: tuple[str, ...]  # phases of .locate where its residual lives
    measures: tuple[str, ...]  # gaw_measures keys it moves
    signature: str  # in words
    implemented: bool
    _apply: Callable | None = field(default=None, repr=False)
    family: str = ""  # the physics it models, when several entries model one (asymmetry)
    #: entries whose GAW signature this one reproduces by construction (both a sum of delayed
    #: copies of one waveform): the verdict always lists a qualifying one as a rival
    confusable: tuple[str, ...] = ()
    #: parameters of a forward-level entry that act on the simulated waveforms only (no new
    #: simulation when they change), like ``lr_stiffness``'s phase lag
    waveform_params: tuple[str, ...] = ()
    #: simpler catalogue entries this one reduces to: ``(simpler, params)`` — with ``params`` at
    #: their null values this entry *is* ``simpler`` (the phase/amplitude asymmetry at zero phase
    #: difference is ``A (1 + lr_amp) / 2``, a scale error). Used by the nested check (section 3)
    nests: tuple[tuple[str, tuple[str, ...]], ...] = ()
    #: parameters of an observation-level entry that the sampler explores with the material
    #: parameters instead of the quadrature (a third integrated dimension would cost ~10x)
    sampled_params: tuple[str, ...] = ()

    @property
    def integrable(self) -> tuple[str, ...]:
        """Parameters that can be integrated out per simulation by quadrature
        (:mod:`.quadrature`): an observation-level entry's (less ``sampled_params``),
        ``waveform_params`` otherwise."""
        if self.kind == "observation":
            return tuple(n for n in self.param_names if n not in self.sampled_params)
        return tuple(self.waveform_params)

    @property
    def physics(self) -> str:
        """What is named: the family (e.g. "asymmetry" for ``lr_stiffness``) or the name."""
        return self.family or self.name

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    def bounds(self) -> dict[str, tuple[float, float]]:
        return {p.name: (p.lo, p.hi) for p in self.params}

    def sample_prior(self, n: int, rng: np.random.Generator) -> np.ndarray:
        lo = np.array([p.lo for p in self.params])
        hi = np.array([p.hi for p in self.params])
        return lo + (hi - lo) * rng.random((n, len(self.params)))

    def apply(self, base, theta, fps: float | None = None, **kw):
        """Extended observation of ``base`` (SimResult or GAW array) for parameters ``theta``
        (mapping name -> value, or a sequence in ``param_names`` order)."""
        if not self.implemented or self._apply is None:
            if self.implemented:
                raise NotImplementedError(
                    f"extension {self.name!r} is fitted through vfcore.diagnose.fit "
                    "(observe_extended / extended_config), not apply()"
                )
            raise NotImplementedError(
                f"extension {self.name!r} ({self.kind}) is catalogued but not implemented: it needs a change to "
                "the forward model (see docs/diagnose.md)"
            )
        th = dict(theta) if isinstance(theta, dict) else dict(zip(self.param_names, np.atleast_1d(theta)))
        missing = set(self.param_names) - set(th)
        if missing:
            raise ValueError(f"extension {self.name!r} missing parameters {sorted(missing)}")
        for p in self.params:
            v = float(th[p.name])
            if not (p.lo <= v <= p.hi):
                raise ValueError(f"{p.name}={v} outside its prior [{p.lo}, {p.hi}] {p.unit}")
        return self._apply(base, th, fps, **kw)


def _gaw_fps(base, fps):
    if hasattr(base, "gaw"):
        return np.asarray(base.gaw, dtype=float), float(fps if fps is not None else base.fps)
    if fps is None:
        raise ValueError("fps is required when base is a GAW array")
    return np.asarray(base, dtype=float), float(fps)


# ---------------------------------------------------------------- observation-level operators
def leak_extra(gaw, leak_mm2: float, chink_fraction: float = 0.0) -> np.ndarray:
    """Area the incomplete closure adds to the GAW, mm^2: ``max(0, leak_mm2 - chink_fraction * A)``.

    A gap of area ``a = leak_mm2`` (its area when the membranous folds are closed) that lies a
    fraction ``f = chink_fraction`` inside the membranous glottis: a chink of width ``g`` over the
    length ``l``, with ``f = l / L`` of the fold length ``L`` and ``a = g l``. Where the membranous
    opening ``W(t) = A(t) / L`` is wider than ``g`` the chink is inside it and adds nothing, so the
    glottis' area is ``W (L - l) + l max(W, g) = A + a max(0, 1 - W / g) = A + max(0, a - f A)``.
    ``f = 0`` is a gap outside the membranous glottis (cartilaginous, constant: ``A + a``);
    ``f = 1`` a uniform gap along the whole length (the area cannot fall below ``a``)."""
    g = np.asarray(gaw, dtype=float)
    return np.maximum(0.0, float(leak_mm2) - float(chink_fraction) * g)


def apply_leak(gaw, leak_mm2: float, chink_fraction: float = 0.0) -> np.ndarray:
    """Posterior-gap / incomplete-closure leak: ``A + max(0, leak_mm2 - chink_fraction * A)``
    (:func:`leak_extra`); ``chink_fraction = 0`` is a constant parallel area."""
    g = np.asarray(gaw, dtype=float)
    return g + leak_extra(g, leak_mm2, chink_fraction)


def leak_flow(leak_mm2, p_sub_pa, rho: float = RHO_AIR):
    """Bernoulli flow through a rigid leak of area A (mm^2, a number or one per sample) at
    transglottal pressure p, m^3/s: ``Q = A sqrt(2 p / rho)`` (Zañartu et al. 2014: the posterior
    gap carries DC flow)."""
    a = np.asarray(leak_mm2, dtype=float)
    q = a * 1e-6 * np.sqrt(2.0 * np.maximum(np.asarray(p_sub_pa, dtype=float), 0.0) / rho)
    return float(q) if np.ndim(q) == 0 else q


def apply_scale(gaw, scale: float) -> np.ndarray:
    """Camera calibration (px -> mm^2) error: multiplicative area scale."""
    return np.asarray(gaw, dtype=float) * float(scale)


def apply_exposure(gaw, fps: float, exposure_fraction: float, edge: str = "reflect") -> np.ndarray:
    """Exposure averaging: each frame is the mean of the area over a centred exposure window of
    ``tau = exposure_fraction / fps`` seconds.

    A centred boxcar of width ``tau`` has transfer function ``sinc(f tau)`` (numpy's normalised
    sinc) and zero phase; it is applied in the frequency domain to the band-limited (trigonometric)
    interpolant of the frames. ``edge="periodic"`` treats the record as one period of a periodic
    signal: exact when it holds whole periods (a sine's amplitude is multiplied by exactly
    ``sinc(f tau)``). ``edge="reflect"`` (default, for arbitrary records) even-reflects the record
    to length 2n first so the periodic extension has no jump at the ends; then the result is
    approximate near the ends (a kink remains in the derivative).
    """
    x = np.asarray(gaw, dtype=float)
    tau = float(exposure_fraction) / float(fps)
    if tau == 0 or x.size < 2:
        return x.copy()
    if edge not in ("reflect", "periodic"):
        raise ValueError(f"edge must be 'reflect' or 'periodic', got {edge!r}")
    ext = np.concatenate([x, x[::-1]]) if edge == "reflect" else x
    f = np.fft.rfftfreq(ext.size, d=1.0 / fps)
    y = np.fft.irfft(np.fft.rfft(ext) * np.sinc(f * tau), n=ext.size)
    return y[: x.size]


def apply_frame_rate(gaw, fps: float, rate_ratio: float) -> np.ndarray:
    """Frame-rate mismatch: the true frame rate is ``rate_ratio * fps`` while the recording is
    labelled ``fps``. A simulation sampled at the labelled rate, y(t_k), is seen by such a camera as
    ``y(t_k / rate_ratio)`` (linear interpolation; frames beyond the simulated span hold the last
    value). rate_ratio > 1: the recording looks slower (apparent f0 = f0 / rate_ratio)."""
    x = np.asarray(gaw, dtype=float)
    t = np.arange(x.size) / fps
    return np.interp(t / float(rate_ratio), t, x)


def _obs_apply(fn):
    def wrapped(base, th, fps, **kw):
        g, f = _gaw_fps(base, fps)
        return fn(g, f, th)

    return wrapped


def _leak(base, th, fps, **kw):
    """GAW + the gap's area (:func:`leak_extra`); for a SimResult also returns flow + the Bernoulli
    flow through the open part of the gap (p_sub of its params)."""
    g, f = _gaw_fps(base, fps)
    extra = leak_extra(g, th["leak_mm2"], th["chink_fraction"])
    out = g + extra
    if hasattr(base, "flow") and hasattr(base, "params") and base.flow.size:
        # SimResult.flow is sampled with SimResult.gaw (one value per frame)
        q = np.asarray(base.flow, dtype=float) + leak_flow(extra, base.params.p_sub - base.config.p_sup)
        return {"gaw": out, "flow": q}
    return out


def _sep(base, th, fps, simulate_fn=None, **kw):
    """Re-simulate ``base`` (a SimResult) with ``SimConfig(sep_ratio=...)``."""
    if not hasattr(base, "params") or not hasattr(base, "config"):
        raise TypeError("sep_ratio is a forward-model extension: pass the base SimResult")
    if simulate_fn is None:
        from ..forward import simulate as simulate_fn
    cfg = dataclasses.replace(base.config, sep_ratio=float(th["sep_ratio"]))
    return simulate_fn(base.params, cfg)


CATALOGUE: dict[str, Extension] = {
    e.name: e
    for e in [
        Extension(
            "leak",
            "observation",
            (
                ExtParam(
                    "leak_mm2",
                    0.0,
                    3.0,
                    "mm^2",
                    "posterior glottal gap areas of a few mm^2 (Zañartu et al. 2014, JASA)",
                    null=0.0,
                ),
                ExtParam(
                    "chink_fraction",
                    0.0,
                    1.0,
                    "-",
                    "fraction of the fold length the gap spans inside the membranous glottis: 0 = a "
                    "cartilaginous gap (constant area), 1 = a uniform gap along the length; a chink is "
                    "hidden where the membranous opening is wider (chosen bounds, docs/diagnose.md)",
                ),
            ),
            ("closed",),
            ("min_area_mm2", "glottal_gap_index", "open_quotient", "closing_quotient"),
            "area floor above zero during the closed phase; GGI > 0; DC flow; a membranous chink is "
            "hidden as the folds open (the added area falls as the GAW rises)",
            True,
            _leak,
        ),
        Extension(
            "scale",
            "observation",
            (
                ExtParam(
                    "scale",
                    0.8,
                    1.2,
                    "-",
                    "px-to-mm calibration error of laryngoscopic images (+-20 %; Deng, Hadwin & Peterson 2019)",
                    null=1.0,
                ),
            ),
            ("peak", "opening", "closing"),
            ("amplitude_mm2", "min_area_mm2", "max_area_mm2"),
            "residual proportional to the GAW itself (largest at the peak); timing quotients unchanged",
            True,
            _obs_apply(lambda g, f, th: apply_scale(g, th["scale"])),
        ),
        Extension(
            "exposure",
            "observation",
            (
                ExtParam(
                    "exposure_fraction",
                    0.0,
                    1.0,
                    "-",
                    "exposure time / frame interval, at most 1 (Deng, Hadwin & Peterson 2019)",
                    null=0.0,
                ),
            ),
            ("peak", "closed"),
            ("amplitude_mm2", "hrf_db", "naq", "amplitude_quotient_s", "speed_quotient"),
            "peaks lowered and corners rounded (low-pass sinc(f tau)); HRF falls, closing slope shallower",
            True,
            _obs_apply(lambda g, f, th: apply_exposure(g, f, th["exposure_fraction"])),
        ),
        Extension(
            "frame_rate",
            "observation",
            (
                ExtParam(
                    "rate_ratio",
                    0.9,
                    1.1,
                    "-",
                    "true/labelled frame rate, +-10 % (chosen bound; Deng, Hadwin & Peterson 2019 study fps)",
                    null=1.0,
                ),
            ),
            ("opening", "closing"),
            ("f0_hz", "period_s"),
            "f0 offset; residual grows along the record as the phases drift (antisymmetric at edges)",
            True,
            _obs_apply(lambda g, f, th: apply_frame_rate(g, f, th["rate_ratio"])),
        ),
        Extension(
            "sep_ratio",
            "forward",
            (
                ExtParam(
                    "sep_ratio",
                    1.0,
                    1.6,
                    "-",
                    "separation where A >= sep_ratio * A_min; range of empirical separation criteria "
                    "(Pelorson et al. 1994, JASA); default 1.3 here; JASA-EL 2021 flow-model selection",
                    null=1.3,
                ),
            ),
            ("opening", "closing"),
            ("speed_quotient", "closing_quotient", "naq", "f0_hz", "amplitude_mm2"),
            "GAW skew (opening vs closing asymmetry) and amplitude; driving-pressure timing",
            True,
            _sep,
        ),
        Extension(
            "epithelium",
            "forward",
            (
                ExtParam(
                    "E_epith_kpa",
                    5.0,
                    200.0,
                    "kPa",
                    "membrane stiffness of the surface layer; vocal-fold epithelium is much stiffer than the SLP "
                    "(chosen bounds, docs/diagnose.md)",
                ),
                ExtParam(
                    "h_epith_mm",
                    0.0,
                    0.1,
                    "mm",
                    "membrane thickness; vocal-fold epithelium is 0.03-0.1 mm thick (Hirano 1981); 0 = no "
                    "membrane, the base model (its stiffness and damping both vanish with the thickness)",
                    null=0.0,
                ),
            ),
            ("closing", "closed", "opening"),
            ("closing_quotient", "naq", "hrf_db", "f0_hz", "amplitude_mm2"),
            "stiffer thin surface layer: higher f0 for the same bulk moduli, sharper closure, more HF energy",
            True,
            None,
        ),
        Extension(
            "zipper",
            "observation",
            (
                ExtParam(
                    "ap_phase_lag",
                    0.0,
                    0.4,
                    "cycles",
                    "anterior-posterior phase difference of high-speed recordings (zipper-like closure; chosen bounds)",
                    null=0.0,
                ),
                ExtParam(
                    "end_fraction",
                    0.0,
                    0.5,
                    "-",
                    "fraction of the length over which the ends are held (taper)",
                    null=0.0,
                ),
                ExtParam(
                    "ap_power",
                    0.5,
                    3.0,
                    "-",
                    "shape of the delay along the length, delay ~ (y/L)^p: 1 = a wave at constant speed, "
                    "> 1 = most of the length in phase and the lag gathered at the posterior end, < 1 at "
                    "the anterior end (chosen bounds, docs/diagnose.md)",
                ),
            ),
            ("opening", "closing", "peak"),
            ("speed_quotient", "closing_quotient", "glottal_gap_index", "amplitude_mm2"),
            "anterior-posterior phase difference: gradual (zipper-like) opening/closing, rounded corners",
            True,
            None,
            confusable=("asymmetry",),
            sampled_params=("ap_power",),
        ),
        Extension(
            "subglottal",
            "forward",
            (
                ExtParam(
                    "f_sub_hz",
                    200.0,
                    900.0,
                    "Hz",
                    "first subglottal resonance: ~500-700 Hz in humans, lower in rigs with long subglottal tubes",
                ),
                ExtParam(
                    "log10_Z_sub",
                    SUB_LOG10_Z_OFF,
                    7.0,
                    "log10(Pa s/m^3)",
                    "peak input impedance of the resonance: ~1e6 for a human trachea; the lower bound stands for no "
                    "coupling, the base model (docs/diagnose.md, section 4)",
                    null=SUB_LOG10_Z_OFF,
                ),
            ),
            ("opening", "peak", "closing"),
            ("hrf_db", "f0_hz", "shr", "amplitude_mm2"),
            "ripple at the subglottal resonance superposed on the GAW; f0 and amplitude change (p_in varies)",
            True,
            None,
        ),
        Extension(
            "asymmetry",
            "observation",
            (
                ExtParam("lr_phase", 0.0, 0.25, "cycles", "left-right phase difference (chosen bounds)", null=0.0),
                ExtParam("lr_amp", 0.5, 1.5, "-", "right/left amplitude ratio (chosen bounds)", null=1.0),
            ),
            ("opening", "closing", "closed"),
            ("open_quotient", "speed_quotient", "glottal_gap_index"),
            "left-right imbalance: phase lag between folds, longer open phase, skewed opening/closing",
            True,
            None,
            family="asymmetry",
            confusable=("zipper",),
            nests=(("scale", ("lr_phase",)),),
        ),
        Extension(
            "lr_stiffness",
            "forward",
            (
                ExtParam(
                    "log2_lr_Q",
                    -1.0,
                    1.0,
                    "-",
                    "log2 of the right/left ratio of the three Young's moduli: a unilateral tension imbalance "
                    "(e.g. paresis; Steinecke & Herzel 1995, JASA); [-1, 1] = ratios 0.5-2 (chosen bounds)",
                    null=0.0,
                ),
                ExtParam(
                    "lr_lag",
                    -0.25,
                    0.25,
                    "cycles",
                    "phase lag of the right fold behind the left (chosen bounds)",
                    null=0.0,
                ),
            ),
            ("opening", "closing", "closed", "peak"),
            ("open_quotient", "speed_quotient", "closing_quotient", "glottal_gap_index", "amplitude_mm2"),
            "two folds of different stiffness entrained 1:1: the GAW is the mean of two differently shaped cycles "
            "(amplitude, open quotient and skew differ; shoulders on opening or closing)",
            True,
            None,
            family="asymmetry",
            waveform_params=("lr_lag",),
        ),
    ]
}


def get(name: str) -> Extension:
    try:
        return CATALOGUE[name]
    except KeyError:
        raise KeyError(f"unknown extension {name!r}; known: {sorted(CATALOGUE)}") from None


def physics_of(name: str | None) -> str | None:
    """The physics an entry names (its family, e.g. "asymmetry" for ``lr_stiffness``); a name
    outside the catalogue (or None) is returned as it is."""
    ext = CATALOGUE.get(name) if name is not None else None
    return ext.physics if ext is not None else name


def implemented(kind: str | None = None) -> list[str]:
    return [n for n, e in CATALOGUE.items() if e.implemented and (kind is None or e.kind == kind)]


def matching(phase: str | None = None, measures=()) -> list[str]:
    """Catalogue entries whose signature covers ``phase`` and/or any of ``measures`` (candidate list)."""
    out = []
    for n, e in CATALOGUE.items():
        if (phase is None or phase in e.phases) and (not measures or set(measures) & set(e.measures)):
            out.append(n)
    return out
