"""What the camera records of a simulation under an observation-level catalogue entry (leak, scale,
exposure, frame rate, zipper, phase/amplitude asymmetry), and the two-fold combination of
``lr_stiffness``. The operators act on the oversampled simulated area
(:attr:`vfcore.result.SimResult.gaw_hr`, ``HR_OVERSAMPLE`` times the camera rate) so that they stay
continuous in their parameters (a frame-rate grid would quantise time shifts); :mod:`.fit` applies
them inside the extended models' likelihood."""

from __future__ import annotations

import math

import numpy as np

from ..measures import estimate_f0
from ..result import HR_OVERSAMPLE
from ._kernels import strip_sum
from .extensions import apply_leak

__all__ = ["observe_extended", "observer", "entrain_pair", "pair_observer", "right_fold_params", "delayed_copy"]


def _period_s(hr: np.ndarray, fps: float) -> float:
    f0 = estimate_f0(hr[::HR_OVERSAMPLE], fps)
    if not (math.isfinite(f0) and f0 > 0):
        raise RuntimeError("the simulation does not oscillate: the extension needs its period")
    return 1.0 / f0


def observe_extended(name: str, hr: np.ndarray, fps: float, phi: dict, length_mm: float = 17.0) -> np.ndarray:
    """What the camera records of an oversampled simulated area ``hr`` (mm^2, rate
    ``HR_OVERSAMPLE * fps``) under observation-level extension ``name`` with parameters ``phi``
    (:func:`observer` for many ``phi`` on one simulation).

    - leak: ``A + max(0, leak_mm2 - chink_fraction * A)`` (a rigid posterior gap, hidden by the
      membranous opening where that is wider: :func:`.extensions.leak_extra`).
    - scale: ``scale * A`` (pixel-size / viewing-angle calibration error).
    - exposure: centred boxcar average over ``exposure_fraction / fps`` s (exact integral of the
      piecewise-linear waveform, continuous in the fraction).
    - frame_rate: ``A(t / rate_ratio)`` (the camera's true rate is ``rate_ratio * fps``).
    - zipper: the fold length split into 24 strips; strip ``y`` moves like the section delayed by
      ``ap_phase_lag * T0 * ((y / L)^p - 1/2)`` (``p = ap_power``; 1 = a wave along the length at
      constant speed) and scaled by the end-constraint taper ``min(1, y / (e L), (L - y) / (e L))``
      with ``e = end_fraction``; area = sum of strips.
    - asymmetry: two folds with the section's motion, the second delayed by
      ``lr_phase * T0`` and scaled by ``lr_amp``: ``A/2 + lr_amp * A(t - lr_phase T0)/2``.
    """
    return observer(name, hr, fps, length_mm)(phi)


def observer(name: str, hr: np.ndarray, fps: float, length_mm: float = 17.0):
    """``phi -> observed oversampled area`` for one simulation (see :func:`observe_extended`);
    what does not depend on ``phi`` (the period, the running integral) is computed once."""
    rate = HR_OVERSAMPLE * fps
    y = np.asarray(hr, dtype=float)
    t = np.arange(y.size) / rate
    if name == "leak":
        return lambda phi: apply_leak(y, phi["leak_mm2"], phi["chink_fraction"])
    if name == "scale":
        return lambda phi: y * phi["scale"]
    if name == "exposure":
        c = np.concatenate([[0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) / rate)])

        def exposure(phi):
            tau = phi["exposure_fraction"] / fps
            if tau <= 0:
                return y.copy()
            lo = np.clip(t - tau / 2, 0, t[-1])
            hi = np.clip(t + tau / 2, 0, t[-1])
            w = hi - lo
            return np.where(w > 0, (np.interp(hi, t, c) - np.interp(lo, t, c)) / np.where(w > 0, w, 1), y)

        return exposure
    if name == "frame_rate":
        return lambda phi: np.interp(t / phi["rate_ratio"], t, y)
    if name in ("zipper", "asymmetry"):
        T0 = _period_s(y, fps)
        pad = int(math.ceil(0.5 * T0 * rate)) + 2  # the longest delay of either model, in samples
        yp = np.concatenate([np.full(pad, y[0]), y, np.full(pad, y[-1])])
        if name == "asymmetry":
            return lambda phi: (
                0.5 * y + 0.5 * phi["lr_amp"] * delayed_copy(yp, pad, y.size, phi["lr_phase"] * T0 * rate)
            )
        n = 24
        ys = (np.arange(n) + 0.5) / n  # strip centres, fraction of length

        def zipper(phi):
            e = phi["end_fraction"]
            taper = np.ones(n) if e <= 0 else np.minimum(1.0, np.minimum(ys, 1 - ys) / e)
            shape = ys ** phi["ap_power"] - 0.5  # in [-1/2, 1/2]
            # one fused pass per strip (numba; the same sums as shifting each strip, to ~1e-15)
            return strip_sum(y, phi["ap_phase_lag"] * T0 * rate * shape, taper / n)

        return zipper
    raise ValueError(f"{name!r} is not an observation-level extension")


def delayed_copy(yp: np.ndarray, pad: int, n: int, d: float) -> np.ndarray:
    """``y(i - d)`` for ``i = 0..n-1`` (``d`` in samples, ``|d| < pad - 1``) by linear
    interpolation, from ``yp`` = ``y`` padded with ``pad`` copies of its end values on each side
    (so the ends are held, as ``np.interp`` holds them): two shifted slices instead of a search."""
    k = math.floor(d)
    if abs(k) >= pad - 1:  # beyond the padding: hold the ends by search
        t = np.arange(n, dtype=float)
        return np.interp(t - d, t, yp[pad : pad + n])
    w = d - k
    a = yp[pad - k : pad - k + n]  # y(i - k)
    b = yp[pad - k - 1 : pad - k - 1 + n]  # y(i - k - 1)
    return (1.0 - w) * a + w * b


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
    left fold's cycle coordinate (k at its k-th opening instant, linear in between, at the mean
    period beyond the first and the last), the right fold is read where its own cycle coordinate
    is ``c_L(t) - lag_cycles`` (folded by whole cycles only where that instant leaves its record).
    A piecewise-linear warp between opening instants, so the identical fold (ratio 1, lag 0)
    returns ``A_L`` exactly, and a nearly identical one nearly ``A_L``, ends included. The folds'
    coupling through the shared flow, which sets the common f0 in reality, is not modelled
    (:ref:`diagnose`)."""
    return pair_observer(left_hr, right_hr, fps)(lag_cycles)


def pair_observer(left_hr: np.ndarray, right_hr: np.ndarray, fps: float):
    """``lag_cycles -> entrain_pair(left_hr, right_hr, fps, lag_cycles)``, with the folds'
    opening instants found once."""
    rate = HR_OVERSAMPLE * fps
    yl = np.asarray(left_hr, dtype=float)
    yr = np.asarray(right_hr, dtype=float)
    ol, orr = _opening_instants(yl, rate), _opening_instants(yr, rate)
    if ol.size < 2 or orr.size < 2:
        raise RuntimeError("too few cycles to entrain the folds")
    t = np.arange(yl.size) / rate
    tr = np.arange(yr.size) / rate
    # cycle coordinate of the left fold: k at its k-th opening instant, linear in between, at the
    # mean period before the first and after the last; the right fold is read at the instant of
    # the same coordinate minus the lag, by the same rule on its own opening instants. Only an
    # instant outside the right fold's record is folded by whole cycles into the span of its
    # opening instants, so that the same fold at lag 0 is read at (to round-off) its own instants
    # over the whole record, the partial cycles at either end included.
    T_L = (ol[-1] - ol[0]) / (ol.size - 1)
    c0 = np.interp(t, ol, np.arange(ol.size, dtype=float))
    c0 = np.where(t < ol[0], (t - ol[0]) / T_L, np.where(t > ol[-1], ol.size - 1 + (t - ol[-1]) / T_L, c0))
    top = orr.size - 1
    k_r = np.arange(orr.size, dtype=float)
    T_R = (orr[-1] - orr[0]) / top
    same = yl.shape == yr.shape and bool(np.array_equal(yl, yr))

    def observe(lag_cycles: float) -> np.ndarray:
        if same and float(lag_cycles) == 0.0:  # the pair's null: the fold itself, exactly
            return yl.copy()
        c = c0 - float(lag_cycles)
        at = np.where(c < 0, orr[0] + c * T_R, np.where(c > top, orr[-1] + (c - top) * T_R, np.interp(c, k_r, orr)))
        out = (at < tr[0]) | (at > tr[-1])
        if out.any():
            cf = c[out]
            cf = np.where(cf > top, cf - np.ceil(cf - top), cf)
            cf = np.where(cf < 0, cf + np.ceil(-cf), cf)
            at[out] = np.interp(cf, k_r, orr)
        return 0.5 * yl + 0.5 * np.interp(at, tr, yr)

    return observe
