"""Fit extended models: the base forward model plus one catalogued extension.

An extended fit estimates the base model's parameters (those of the base ``Problem``'s prior)
*jointly* with the extension's parameters, with the same likelihood (Eq. 15, sigma_e, the same
compared frames and the same alignment) as the base fit, so the log-evidences of base and
extended fits are comparable (docs/diagnose.md, "Refits").

Extensions act in one of two ways (``Extension.kind``):

- **observation** (leak, scale, exposure, frame_rate, zipper, asymmetry): the simulation is the
  base model's; the extension maps its glottal area, at 10x the camera rate
  (:attr:`vfcore.result.SimResult.gaw_hr`), to what the camera records, before alignment.
  These operators are defined here, on the oversampled waveform, so that they stay continuous
  in their parameters (a frame-rate grid would quantise time shifts).
- **forward** (sep_ratio, epithelium, subglottal): a ``SimConfig`` field of the forward model,
  so each draw re-simulates. ``lr_stiffness`` (two folds of different stiffness) simulates a
  second, right fold with its moduli scaled and combines the two (:func:`entrain_pair`), so each
  draw costs two simulations.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..measures import estimate_f0
from ..result import HR_OVERSAMPLE
from ..inference.prior import Prior
from ..inference.problem import Evaluation, Problem, score_results
from .extensions import Extension, get

__all__ = ["ExtendedPrior", "ExtendedEvaluator", "observe_extended", "extended_config", "fit_extended",
           "entrain_pair", "right_fold_params"]


# ------------------------------------------------------------------------------------ prior
@dataclass(frozen=True, eq=False)
class ExtendedPrior(Prior):
    """Uniform prior over the base prior's parameters followed by an extension's parameters.

    ``names`` lists the base names (in ``PARAM_NAMES`` order) then the extension's.
    ``split(theta)`` returns (base theta, {extension name: value}).
    """

    base: Prior | None = None
    extension: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.base, Prior):
            raise ValueError("ExtendedPrior needs a base Prior")
        ext = get(self.extension)
        b = dict(self.base.bounds)
        for p in ext.params:
            if p.name in b:
                raise ValueError(f"extension parameter {p.name!r} clashes with a base parameter")
            b[p.name] = (float(p.lo), float(p.hi))
        object.__setattr__(self, "bounds", b)
        object.__setattr__(self, "fixed", dict(self.base.fixed))

    @property
    def n_base(self) -> int:
        return self.base.ndim

    def split(self, theta) -> tuple[np.ndarray, dict[str, float]]:
        theta = np.asarray(theta, dtype=float)
        nb = self.n_base
        return theta[:nb], dict(zip(self.names[nb:], map(float, theta[nb:])))

    def to_params(self, theta):
        return self.base.to_params(self.split(theta)[0])

    def to_dict(self) -> dict:
        return {"base": self.base.to_dict(), "extension": self.extension}

    def __repr__(self) -> str:
        return f"ExtendedPrior({self.base!r} + {self.extension})"


# ------------------------------------------------------------------- observation operators
def _shift(y: np.ndarray, rate: float, delay_s) -> np.ndarray:
    """``y(t - delay)`` on the same grid (linear interpolation; ends held)."""
    t = np.arange(y.size) / rate
    return np.interp(t - delay_s, t, y)


def _period_s(hr: np.ndarray, fps: float) -> float:
    f0 = estimate_f0(hr[::HR_OVERSAMPLE], fps)
    if not (math.isfinite(f0) and f0 > 0):
        raise RuntimeError("the simulation does not oscillate: the extension needs its period")
    return 1.0 / f0


def observe_extended(name: str, hr: np.ndarray, fps: float, phi: dict, length_mm: float = 17.0) -> np.ndarray:
    """What the camera records of an oversampled simulated area ``hr`` (mm^2, rate
    ``HR_OVERSAMPLE * fps``) under observation-level extension ``name`` with parameters ``phi``.

    - leak: ``A + leak_mm2`` (a parallel, rigid posterior gap).
    - scale: ``scale * A`` (pixel-size / viewing-angle calibration error).
    - exposure: centred boxcar average over ``exposure_fraction / fps`` s (exact integral of the
      piecewise-linear waveform, continuous in the fraction).
    - frame_rate: ``A(t / rate_ratio)`` (the camera's true rate is ``rate_ratio * fps``).
    - zipper: the fold length split into 24 strips; strip ``y`` moves like the section delayed by
      ``ap_phase_lag * T0 * (y / L - 1/2)`` and scaled by the end-constraint taper
      ``min(1, y / (e L), (L - y) / (e L))`` with ``e = end_fraction``; area = sum of strips.
    - asymmetry: two folds with the section's motion, the second delayed by
      ``lr_phase * T0`` and scaled by ``lr_amp``: ``A/2 + lr_amp * A(t - lr_phase T0)/2``.
    """
    rate = HR_OVERSAMPLE * fps
    y = np.asarray(hr, dtype=float)
    if name == "leak":
        return y + phi["leak_mm2"]
    if name == "scale":
        return y * phi["scale"]
    if name == "exposure":
        tau = phi["exposure_fraction"] / fps
        if tau <= 0:
            return y.copy()
        t = np.arange(y.size) / rate
        c = np.concatenate([[0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) / rate)])
        lo = np.clip(t - tau / 2, 0, t[-1])
        hi = np.clip(t + tau / 2, 0, t[-1])
        w = hi - lo
        return np.where(w > 0, (np.interp(hi, t, c) - np.interp(lo, t, c)) / np.where(w > 0, w, 1), y)
    if name == "frame_rate":
        t = np.arange(y.size) / rate
        return np.interp(t / phi["rate_ratio"], t, y)
    if name == "zipper":
        T0 = _period_s(y, fps)
        n = 24
        ys = (np.arange(n) + 0.5) / n                    # strip centres, fraction of length
        e = phi["end_fraction"]
        taper = np.ones(n) if e <= 0 else np.minimum(1.0, np.minimum(ys, 1 - ys) / e)
        out = np.zeros_like(y)
        for yk, wk in zip(ys, taper):
            out += wk * _shift(y, rate, phi["ap_phase_lag"] * T0 * (yk - 0.5))
        return out / n
    if name == "asymmetry":
        T0 = _period_s(y, fps)
        return 0.5 * y + 0.5 * phi["lr_amp"] * _shift(y, rate, phi["lr_phase"] * T0)
    raise ValueError(f"{name!r} is not an observation-level extension")


def _opening_instants(y: np.ndarray, rate: float) -> np.ndarray:
    """Upward crossings (s, linear interpolation) of the mid-level ``(min + max) / 2``: one
    opening instant per cycle (a crossing closer than half the autocorrelation period to the
    previous one is a ripple and is dropped)."""
    m = 0.5 * (float(np.min(y)) + float(np.max(y)))
    i = np.nonzero((y[:-1] < m) & (y[1:] >= m))[0]
    t = (i + (m - y[i]) / (y[i + 1] - y[i])) / rate
    if t.size < 2:
        raise RuntimeError("fewer than two opening instants: the fold does not oscillate in the window")
    T = _period_s(y, rate / HR_OVERSAMPLE)
    keep = [t[0]]
    for tk in t[1:]:
        if tk - keep[-1] > 0.5 * T:
            keep.append(tk)
    return np.array(keep)


def right_fold_params(params, log2_q: float):
    """The right fold's parameters: E_body, E_lig and E_cover of ``params`` times ``2**log2_q``."""
    q = 2.0 ** float(log2_q)
    return params.replace(E_body=params.E_body * q, E_lig=params.E_lig * q, E_cover=params.E_cover * q)


def entrain_pair(left_hr: np.ndarray, right_hr: np.ndarray, fps: float, lag_cycles: float) -> np.ndarray:
    """Glottal area of two different folds, each simulated as a symmetric section (area ``A_L``,
    ``A_R``), each contributing half its area: ``A_L(t)/2 + A_R(t_R(t))/2``.

    The right fold is entrained 1:1 on the left fold's cycles, cycle by cycle: with ``c_L(t)`` the
    left fold's cycle coordinate (k at its k-th opening instant, linear in between), the right
    fold is read where its own cycle coordinate is ``c_L(t) - lag_cycles`` (folded by whole cycles
    into its record). A piecewise-linear warp between opening instants, so the identical fold
    (ratio 1, lag 0) returns ``A_L`` exactly. The folds' coupling through the shared flow, which
    sets the common f0 in reality, is not modelled (docs/diagnose.md)."""
    rate = HR_OVERSAMPLE * fps
    yl = np.asarray(left_hr, dtype=float)
    yr = np.asarray(right_hr, dtype=float)
    ol, orr = _opening_instants(yl, rate), _opening_instants(yr, rate)
    if ol.size < 2 or orr.size < 2:
        raise RuntimeError("too few cycles to entrain the folds")
    t = np.arange(yl.size) / rate
    # cycle coordinate of the left fold: k at its k-th opening instant, linear in between (mean
    # period outside); the right fold is read at the same coordinate minus the lag, folded by
    # whole cycles into the span of its own opening instants
    T_L = (ol[-1] - ol[0]) / (ol.size - 1)
    c = np.interp(t, ol, np.arange(ol.size, dtype=float))
    c = np.where(t < ol[0], (t - ol[0]) / T_L, np.where(t > ol[-1], ol.size - 1 + (t - ol[-1]) / T_L, c))
    c = c - float(lag_cycles)
    top = orr.size - 1
    c = np.where(c > top, c - np.ceil(c - top), c)
    c = np.where(c < 0, c + np.ceil(-c), c)
    t_r = np.interp(c, np.arange(orr.size, dtype=float), orr)
    return 0.5 * yl + 0.5 * np.interp(t_r, np.arange(yr.size) / rate, yr)


def extended_config(config, name: str, phi: dict):
    """The ``SimConfig`` of a forward-level extension ``name`` with parameters ``phi``."""
    if name == "sep_ratio":
        return dataclasses.replace(config, sep_ratio=phi["sep_ratio"])
    if name == "epithelium":
        return dataclasses.replace(config, epithelium_E_kpa=phi["E_epith_kpa"],
                                   epithelium_h_mm=phi.get("h_epith_mm", 0.05))
    if name == "subglottal":
        return dataclasses.replace(config, subglottal_modes=(
            (phi["f_sub_hz"], phi.get("zeta_sub", 0.1), 10.0 ** phi["log10_Z_sub"]),))
    raise ValueError(f"{name!r} is not a forward-level extension")


# -------------------------------------------------------------------------------- evaluator
class ExtendedEvaluator:
    """Picklable batch function ``thetas (k, d_base + d_ext) -> Evaluation`` for an extended
    model; the likelihood, compared frames and alignment are the base ``problem``'s."""

    def __init__(self, problem: Problem, extension: str):
        self.problem = problem
        self.name = extension
        if not get(extension).implemented:
            raise NotImplementedError(f"extension {extension!r} is not implemented")
        self.prior = ExtendedPrior(bounds={}, base=problem.prior, extension=extension)

    @property
    def extension(self) -> Extension:
        return get(self.name)            # looked up, not stored: catalogue entries hold closures

    def _simulate(self, base_params, phis):
        from ..batch import simulate_many
        ext = self.extension
        cfg = self.problem.config
        if ext.kind == "observation":
            return simulate_many(base_params, cfg, block=32)
        if ext.name == "lr_stiffness":
            return self._simulate_pairs(base_params, phis)
        # forward-level: each draw has its own configuration; the lock-step kernel takes the
        # extensions per row, so the draws still run in blocks
        out: list = [None] * len(base_params)
        rows, cfgs = [], []
        for i, (p, phi) in enumerate(zip(base_params, phis)):
            try:
                cfgs.append(extended_config(cfg, ext.name, phi))
                rows.append(i)
            except Exception as exc:  # noqa: BLE001 - reported per draw
                out[i] = exc
        if rows:
            try:
                res = simulate_many([base_params[i] for i in rows], block=32, configs=cfgs)
            except Exception:  # noqa: BLE001 - find the failing draw(s) one by one
                from ..forward import simulate
                res = []
                for i, c in zip(rows, cfgs):
                    try:
                        res.append(simulate(base_params[i], c))
                    except Exception as exc:  # noqa: BLE001 - reported per draw
                        res.append(exc)
            for i, r in zip(rows, res):
                out[i] = r
        return out

    def _simulate_pairs(self, base_params, phis):
        """Two folds per draw (left: the base parameters; right: :func:`right_fold_params`), all
        rows in one lock-step batch; each draw's result is the left fold's with its area replaced
        by :func:`entrain_pair` (flow and contact stay the left fold's)."""
        from ..batch import simulate_many
        cfg = self.problem.config
        n = len(base_params)
        rights = [right_fold_params(p, phi["log2_lr_Q"]) for p, phi in zip(base_params, phis)]
        res = simulate_many(list(base_params) + rights, cfg, block=32)
        out: list = []
        for i, phi in enumerate(phis):
            left, right = res[i], res[n + i]
            if not left.ok:
                out.append(left)
                continue
            if not right.ok:
                out.append(RuntimeError(f"right fold: {right.message}"))
                continue
            try:
                hr = entrain_pair(left.gaw_hr, right.gaw_hr, cfg.fps, phi["lr_lag"])
                out.append(dataclasses.replace(left, gaw_hr=hr, gaw=hr[::HR_OVERSAMPLE].copy()))
            except Exception as exc:  # noqa: BLE001 - reported per draw
                out.append(exc)
        return out

    def __call__(self, thetas) -> Evaluation:
        pb = self.problem
        thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
        splits = [self.prior.split(th) for th in thetas]
        results = self._simulate([pb.prior.to_params(b) for b, _ in splits], [phi for _, phi in splits])
        observe = None
        if self.extension.kind == "observation":
            def observe(i, hr):
                return observe_extended(self.name, hr, pb.fps, splits[i][1], pb.config.length_mm)
        return score_results(results, pb, observe)


def fit_extended(problem: Problem, extension: str, *, n_particles: int = 80, seed: int = 0, map=map,
                 chunk_size: int = 40, **smc_options):
    """Tempered-SMC fit of the base model + ``extension`` (joint in all parameters).

    Returns a :class:`vfcore.inference.Posterior` whose ``names`` are the base names followed by
    the extension's, with ``log_evidence`` comparable to the base fit's.
    """
    from ..inference.smc import smc
    ev = ExtendedEvaluator(problem, extension)
    post = smc(ev, prior=ev.prior, n_particles=n_particles, seed=seed, map=map, chunk_size=chunk_size,
               **smc_options)
    post.obs_gaw = problem.obs_compared
    post.fps = problem.fps
    post.info["extension"] = extension
    return post


def _ext(name: str) -> Extension:
    return get(name)
