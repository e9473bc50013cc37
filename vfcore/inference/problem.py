"""The inverse problem: observed GAW, noise model, prior, simulation settings; likelihood.

Likelihood (Hadwin et al. 2019, Eq. 15): the observed glottal area waveform ``y`` (mm^2,
at the camera rate) equals the phase-aligned simulated waveform plus independent
Gaussian noise with standard deviation ``sigma_e`` (mm^2, default 1 mm^2),

    log L(theta) = -1/(2 sigma_e^2) sum_k (y_k - A_k(theta))^2 - n/2 log(2 pi sigma_e^2),

over the ``n_compare`` frames fixed by ``vfcore.observe.alignment_window``. Computed in
log space throughout. A failed simulation has log-likelihood ``-inf``.

``Problem(noise="marginal")`` (not in the paper): ``sigma_e`` is unknown, log-uniform on
``sigma_bounds``, and integrated out per draw (:func:`marginal_gaussian_loglik`; :ref:`inference`,
"Unknown noise level").

``Problem(measurements={"p_sub": (mean, sd)})`` (not in the paper): independent Gaussian
measurements of model parameters (paper units), each adding
``log N(mean | theta_name, sd^2) = -(theta_name - mean)^2 / (2 sd^2) - log(sd sqrt(2 pi))`` to the GAW
log-likelihood of a draw. A GAW cannot fix the common scale of E_body, E_cover, E_lig, p_sub, rho and
eta (:ref:`inference-scale-the-common-scale-what-a`); a measured p_sub (or density) can.

``Problem(area_scale=(k_lo, k_hi))`` (not in the paper): the recording's areas are ``k`` times the true areas
with ``k`` unknown (an uncalibrated video; ``k = (true px/mm / assumed px/mm)^2``), uniform on ``[k_lo, k_hi]``
and integrated out per draw in closed form (:mod:`vfcore.inference.likelihood`; :ref:`inference`, "Unknown
area scale"). It costs no extra simulation. ``None`` (default): the areas are calibrated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

from ..config import SimConfig
from ..measures import estimate_f0
from ..observe import ALIGNMENTS, LAG_SEARCHES, align, align_many, alignment_window
from ..params import PARAM_NAMES, PARAM_UNITS, Params
from .evaluation import Evaluation  # noqa: F401 (re-exported)
from .likelihood import (  # noqa: F401 (re-exported)
    gaussian_loglik,
    marginal_gaussian_loglik,
    sample_area_scale,
    scaled_gaussian_loglik,
    scaled_marginal_gaussian_loglik,
)
from .prior import Prior
from .scoring import (  # noqa: F401
    ProblemEvaluator,
    aligned_loglik,
    contact_means,
    cycle_means,
    evaluate,
    score_results,  # (re-exported)
)


# ---------------------------------------------------------------------------- observation
def validate_observation(gaw, fps: float) -> np.ndarray:
    """Check an observed GAW before any simulation runs; return it as float64 (n,).

    Raises ValueError for: non-numeric / non-1D input, NaN or inf, a constant waveform,
    no detectable oscillation, or fewer than two cycles.
    """
    try:
        fps = float(fps)
    except (TypeError, ValueError):
        raise ValueError(f"fps must be a number, got {fps!r}") from None
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a finite number > 0, got {fps!r}")
    try:
        y = np.asarray(gaw, dtype=float)
    except (TypeError, ValueError):
        raise ValueError("observed GAW must be a 1D array of numbers") from None
    if y.ndim != 1:
        raise ValueError(f"observed GAW must be 1D, got shape {y.shape}")
    if y.size < 4:
        raise ValueError(f"observed GAW has {y.size} frames; at least two cycles are needed")
    bad = ~np.isfinite(y)
    if bad.any():
        raise ValueError(
            f"observed GAW contains {int(bad.sum())} NaN/inf value(s) (first at frame {int(np.argmax(bad))})"
        )
    if float(np.ptp(y)) <= 1e-12 * max(1.0, float(np.max(np.abs(y)))):
        raise ValueError("observed GAW is constant: there is no oscillation to fit")
    f0 = estimate_f0(y, fps)
    if not math.isfinite(f0):
        raise ValueError(
            "observed GAW shows no periodic oscillation (f0 could not be estimated; at least two cycles are needed)"
        )
    n_cycles = y.size * f0 / fps
    if n_cycles < 2.0:
        raise ValueError(
            f"observed GAW spans {n_cycles:.2f} cycles (f0 = {f0:.1f} Hz, {y.size} frames at "
            f"{fps:g} fps); at least two cycles are needed"
        )
    return y


def n_sim_frames(config: SimConfig) -> int:
    """Frames a simulation yields at the camera rate (conservative by one frame)."""
    return int(math.floor((config.duration - config.discard) * config.fps + 1e-9))


# ---------------------------------------------------------------------------- measurements
def validate_measurements(measurements, prior: Prior | None = None) -> dict[str, tuple[float, float]]:
    """``{name: (mean, sd)}`` checked and in ``PARAM_NAMES`` order (paper units).

    ValueError (one line) for: not a mapping, an unknown name, a pair that is not two numbers, a
    non-finite mean or sd, sd <= 0, or (with ``prior``) a parameter the prior does not estimate, which a
    measurement could not inform."""
    if measurements is None:
        return {}
    if not hasattr(measurements, "items"):
        raise ValueError(f"measurements must be a mapping {{name: (mean, sd)}}, got {type(measurements).__name__}")
    out: dict[str, tuple[float, float]] = {}
    for name, pair in measurements.items():
        if name not in PARAM_NAMES:
            raise ValueError(f"measurement of unknown parameter {name!r}; known: {list(PARAM_NAMES)}")
        try:
            if isinstance(pair, (str, bytes)) or len(pair) != 2:
                raise TypeError
            mean, sd = float(pair[0]), float(pair[1])
        except (TypeError, ValueError):
            raise ValueError(
                f"measurement of {name} must be a pair (mean, sd) of numbers in {PARAM_UNITS[name]}, got {pair!r}"
            ) from None
        if not (math.isfinite(mean) and math.isfinite(sd)):
            raise ValueError(f"measurement of {name} must have a finite mean and sd, got ({mean}, {sd})")
        if not sd > 0.0:
            raise ValueError(f"measurement of {name} must have sd > 0 {PARAM_UNITS[name]}, got {sd}")
        if prior is not None and name not in prior.names:
            held = "fixed" if name in prior.fixed else "not estimated"
            raise ValueError(
                f"measurement of {name}: the parameter is {held} in the prior, so a measurement "
                "cannot inform it; estimate it or drop the measurement"
            )
        out[name] = (mean, sd)
    return {n: out[n] for n in PARAM_NAMES if n in out}


def gaussian_measurement_loglik(values, measurements) -> float:
    """Sum over ``measurements`` ``{name: (mean, sd)}`` of ``log N(mean | values[name], sd^2)``;
    ``values``: a ``Params``, a mapping ``{name: value}`` or a full 7-vector in ``PARAM_NAMES`` order."""
    if not measurements:
        return 0.0
    if isinstance(values, Params):
        get = values.as_dict().__getitem__
    elif hasattr(values, "items"):
        get = values.__getitem__
    else:
        arr = np.asarray(values, dtype=float).reshape(-1)
        if arr.size != len(PARAM_NAMES):
            raise ValueError(f"parameter vector must have {len(PARAM_NAMES)} values ({PARAM_NAMES}), got {arr.size}")
        get = dict(zip(PARAM_NAMES, arr.tolist())).__getitem__
    return float(measurement_terms({name: float(get(name)) for name in measurements}, measurements))


def measurement_terms(values, measurements) -> np.ndarray:
    """:func:`gaussian_measurement_loglik` over many draws at once: ``values`` maps each measured name to its
    values (paper units, arrays of one shape); the sum of the Gaussian terms per draw, ``-inf`` where not finite."""
    total = np.zeros(np.shape(next(iter(values.values())))) if values else np.zeros(())
    for name, (mean, sd) in measurements.items():
        z = (np.asarray(values[name], dtype=float) - mean) / sd
        total = total + (-0.5 * z * z - math.log(sd) - 0.5 * math.log(2.0 * math.pi))
    return np.where(np.isfinite(total), total, -np.inf)


# ---------------------------------------------------------------------------- problem
#: noise models: ``fixed`` sigma_e (Eq. 15) or ``marginal`` (sigma_e integrated out, log-uniform prior)
NOISE_MODELS = ("fixed", "marginal")


def model_record(target) -> dict | None:
    """What ``Posterior.model`` records of a fit to ``target``: the settings of its finite-element model
    (``SimConfig.as_record()``), or None for anything but a Problem."""
    return target.config.as_record() if isinstance(target, Problem) else None


@dataclass(frozen=True, eq=False)
class Problem:
    """One inverse problem. Frozen and picklable: it is shipped to every worker.

    ``config.fps`` is set to the observation's ``fps`` (the camera defines the rate).
    ``noise``: ``"fixed"`` (Eq. 15 with ``sigma_e``) or ``"marginal"`` (the noise sd unknown,
    log-uniform on ``sigma_bounds`` mm^2 and integrated out; ``sigma_e`` is then only the noise
    added to predictive bands and p-values where a caller asks for it).
    ``measurements``: ``{name: (mean, sd)}`` in paper units, independent Gaussian measurements of
    estimated parameters whose log density is added to each draw's GAW log-likelihood (they anchor
    the common scale a GAW cannot determine; :ref:`inference`).
    ``area_scale``: ``(k_lo, k_hi)``, the bounds of the uniform prior of an unknown factor ``k`` between the
    recorded and the true area (uncalibrated px/mm), integrated out; ``None``: calibrated areas (``k = 1``).
    """

    obs_gaw: np.ndarray
    fps: float
    prior: Prior
    sigma_e: float = 1.0
    config: SimConfig = field(default_factory=SimConfig)
    model: str = "fe"
    alignment: str = "profile"
    noise: str = "fixed"
    sigma_bounds: tuple = (0.01, 100.0)
    lag_search: str = "window"
    measurements: dict = field(default_factory=dict)
    area_scale: tuple | None = None

    def __post_init__(self) -> None:
        y = validate_observation(self.obs_gaw, self.fps)
        y = y.copy()
        y.setflags(write=False)
        object.__setattr__(self, "obs_gaw", y)
        object.__setattr__(self, "fps", float(self.fps))
        if not isinstance(self.prior, Prior):
            raise ValueError(f"prior must be a Prior, got {type(self.prior).__name__}")
        s = self.sigma_e
        if not (isinstance(s, (int, float, np.floating)) and math.isfinite(float(s)) and float(s) > 0):
            raise ValueError(f"sigma_e must be a finite number > 0 (mm^2), got {s!r}")
        object.__setattr__(self, "sigma_e", float(s))
        if not isinstance(self.config, SimConfig):
            raise ValueError(f"config must be a SimConfig, got {type(self.config).__name__}")
        if self.config.fps != self.fps:
            object.__setattr__(self, "config", self.config.replace(fps=self.fps))
        if self.alignment not in ALIGNMENTS:
            raise ValueError(f"alignment must be one of {ALIGNMENTS}, got {self.alignment!r}")
        if self.noise not in NOISE_MODELS:
            raise ValueError(f"noise must be one of {NOISE_MODELS}, got {self.noise!r}")
        try:
            lo, hi = (float(v) for v in self.sigma_bounds)
        except (TypeError, ValueError):
            raise ValueError(f"sigma_bounds must be two numbers (lo, hi) in mm^2, got {self.sigma_bounds!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 < lo < hi):
            raise ValueError(f"sigma_bounds must satisfy 0 < lo < hi (finite, mm^2), got {self.sigma_bounds!r}")
        object.__setattr__(self, "sigma_bounds", (lo, hi))
        if self.lag_search not in LAG_SEARCHES:
            raise ValueError(f"lag_search must be one of {LAG_SEARCHES}, got {self.lag_search!r}")
        if self.model != "fe":
            raise ValueError(f"unknown model {self.model!r}; only 'fe' is available")
        object.__setattr__(self, "measurements", validate_measurements(self.measurements, self.prior))
        object.__setattr__(self, "area_scale", validate_area_scale(self.area_scale))
        # fails (ValueError) here, before any simulation, if the simulation is too short
        object.__setattr__(self, "_window", alignment_window(y, self.fps, n_sim_frames(self.config), self.lag_search))

    @property
    def window(self) -> tuple[int, int]:
        """(max_lag, n_compare) in frames."""
        return self._window  # type: ignore[attr-defined]

    @property
    def n_compare(self) -> int:
        return self.window[1]

    @property
    def obs_compared(self) -> np.ndarray:
        """The trimmed observation the likelihood compares against, (n_compare,)."""
        return self.obs_gaw[: self.n_compare]

    def to_dict(self) -> dict:
        return {
            "obs_gaw": self.obs_gaw.tolist(),
            "fps": self.fps,
            "sigma_e": self.sigma_e,
            "prior": self.prior.to_dict(),
            "config": self.config.as_dict(),
            "model": self.model,
            "alignment": self.alignment,
            "noise": self.noise,
            "sigma_bounds": list(self.sigma_bounds),
            "lag_search": self.lag_search,
            "measurements": {n: [m, sd] for n, (m, sd) in self.measurements.items()},
            "area_scale": None if self.area_scale is None else list(self.area_scale),
        }

    @classmethod
    def from_dict(cls, d: dict) -> Problem:
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"unknown Problem field(s): {sorted(unknown)}")
        return cls(
            obs_gaw=np.asarray(d["obs_gaw"], dtype=float),
            fps=d["fps"],
            prior=Prior.from_dict(d["prior"]),
            sigma_e=d.get("sigma_e", 1.0),
            config=SimConfig(**d.get("config", {})),
            model=d.get("model", "fe"),
            alignment=d.get("alignment", "profile"),
            noise=d.get("noise", "fixed"),
            sigma_bounds=tuple(d.get("sigma_bounds", (0.01, 100.0))),
            lag_search=d.get("lag_search", "window"),
            measurements=d.get("measurements") or {},
            area_scale=d.get("area_scale"),
        )

    def measurement_loglik(self, params) -> float:
        """The measurements' log density at ``params`` (a ``Params``, ``{name: value}`` or a full
        7-vector; paper units); 0 without measurements."""
        return gaussian_measurement_loglik(params, self.measurements)

    def loglik(self, seg, params=None) -> float:
        """Log-likelihood of an aligned simulated segment ``seg`` (n_compare,) under this problem's
        noise model, Eq. 15 (``fixed``) or :func:`marginal_gaussian_loglik` (``marginal``), plus the
        measurements' term at ``params`` (the draw's full parameters) when ``params`` is given.
        Without ``params`` it is the GAW's term alone, which only differences between waveforms of
        one draw may use: a draw's score must include the measurements. With ``area_scale`` the
        unknown scale of the recorded areas is integrated out (:func:`scaled_gaussian_loglik`,
        :func:`scaled_marginal_gaussian_loglik`); ``seg`` is then the unscaled simulated area."""
        if self.area_scale is not None:
            if self.noise == "marginal":
                ll = scaled_marginal_gaussian_loglik(seg, self.obs_compared, *self.sigma_bounds, *self.area_scale)
            else:
                ll = scaled_gaussian_loglik(seg, self.obs_compared, self.sigma_e, *self.area_scale)
        elif self.noise == "marginal":
            ll = marginal_gaussian_loglik(seg, self.obs_compared, *self.sigma_bounds)
        else:
            ll = gaussian_loglik(seg, self.obs_compared, self.sigma_e)
        if params is not None and self.measurements and ll > -math.inf:
            ll += self.measurement_loglik(params)
        return ll

    def sample_area_scale(self, seg, rng: np.random.Generator) -> float:
        """One draw of the area scale from its conditional posterior given one draw's aligned segment
        ``seg`` (:func:`vfcore.inference.likelihood.sample_area_scale`); ValueError without ``area_scale``."""
        if self.area_scale is None:
            raise ValueError("this problem has no area scale (its areas are calibrated)")
        if self.noise == "marginal":
            return sample_area_scale(seg, self.obs_compared, rng, self.area_scale, sigma_bounds=self.sigma_bounds)
        return sample_area_scale(seg, self.obs_compared, rng, self.area_scale, sigma=self.sigma_e)

    def align(self, sim, sim_hr=None, oversample=None) -> np.ndarray:
        """The segment of a simulated GAW ``sim`` (camera rate; ``sim_hr`` its oversampled copy) aligned to the
        observation over :attr:`window` by :attr:`alignment`, (n_compare,). With ``area_scale`` and the
        ``"profile"`` alignment the lag is chosen a second time against the observation divided by the first
        lag's best scale ``k_hat`` (clipped to the prior's box), so that it minimises ``|k_hat sim - obs|``,
        the residual the likelihood scores, rather than ``|sim - obs|``."""
        kw = {} if sim_hr is None else {"sim_hr": sim_hr, "oversample": oversample}
        seg, _, _ = align(sim, self.obs_gaw, self.fps, self.window, method=self.alignment, **kw)
        if self.area_scale is None or self.alignment != "profile":
            return seg
        k = self._first_scale(seg)
        if k is None:
            return seg
        seg, _, _ = align(sim, self.obs_gaw / k, self.fps, self.window, method=self.alignment, **kw)
        return seg

    def _first_scale(self, seg) -> float | None:
        """The first lag's best area scale ``k_hat`` for :meth:`align`'s second search, clipped to the
        prior's box; None where it is not a positive number (the first lag stands)."""
        ss = float(np.dot(seg, seg))
        k = float(np.dot(self.obs_compared, seg)) / ss if ss > 0 else 0.0
        if not (math.isfinite(k) and k > 0):
            return None
        return min(max(k, self.area_scale[0]), self.area_scale[1])

    def align_many(self, sims_hr, oversample: int) -> np.ndarray:
        """:meth:`align` of several oversampled simulated GAWs of one length (rows of ``sims_hr``), each
        row the same bytes as its own call: segments (m, n_compare). With ``area_scale`` and the
        ``"profile"`` alignment each row's second lag search, against its own scaled observation, runs
        row by row."""
        hr = np.atleast_2d(np.asarray(sims_hr, dtype=float))
        segs, _ = align_many(hr, self.obs_gaw, self.fps, self.window, oversample, method=self.alignment)
        if self.area_scale is None or self.alignment != "profile":
            return segs
        for i, h in enumerate(hr):
            k = self._first_scale(segs[i])
            if k is not None:
                segs[i] = align(
                    h[::oversample],
                    self.obs_gaw / k,
                    self.fps,
                    self.window,
                    method=self.alignment,
                    sim_hr=h,
                    oversample=oversample,
                )[0]
        return segs


def validate_area_scale(area_scale) -> tuple[float, float] | None:
    """``(k_lo, k_hi)`` as floats with ``0 < k_lo < k_hi`` finite, or None; ValueError (one line) otherwise."""
    if area_scale is None:
        return None
    try:
        if isinstance(area_scale, (str, bytes)) or len(area_scale) != 2:
            raise TypeError
        lo, hi = (float(v) for v in area_scale)
    except (TypeError, ValueError):
        raise ValueError(f"area_scale must be two numbers (k_lo, k_hi) or None, got {area_scale!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 < lo < hi):
        raise ValueError(f"area_scale must satisfy 0 < k_lo < k_hi (finite), got {area_scale!r}")
    return lo, hi
