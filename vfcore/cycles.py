"""The cycles of a glottal area waveform (GAW): its f0, its cycle boundaries and per-cycle timings.

All functions take a 1D GAW ``gaw`` (area, normally mm^2) sampled at ``fps`` frames
per second and use numpy only. Sources and exact definitions are collected in
``:ref:`measures`; the measures built on these cycles are in :mod:`vfcore.measures`,
which re-exports every public name here.

Cycle convention
----------------
A glottal cycle runs from one area minimum to the next (:func:`cycle_boundaries`).
Within cycle ``k`` (samples ``b[k] .. b[k+1]``) the *open phase* is the interval in
which the area exceeds ``A_min + level * (A_max - A_min)`` (``level`` = 0.05 by
default, i.e. 5 % of the cycle's peak-to-peak amplitude), with the two crossing
instants found by linear interpolation between samples. ``t_o`` (opening instant),
``t_p`` (instant of maximal area) and ``t_c`` (closing instant) define

- open time ``T_o = t_c - t_o``, opening time ``T_op = t_p - t_o``,
  closing time ``T_cl = t_c - t_p``, period ``T = (b[k+1] - b[k]) / fps``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["DEFAULT_LEVEL", "as_gaw", "cycle_boundaries", "cycle_table", "estimate_f0"]

#: Default open-phase threshold, as a fraction of each cycle's peak-to-peak amplitude.
DEFAULT_LEVEL = 0.05


def estimate_f0(gaw: np.ndarray, fps: float, fmin: float = 40.0, fmax: float = 600.0) -> float:
    """Fundamental frequency from the normalised autocorrelation.

    Parameters
    ----------
    gaw : array_like, shape (n,)
        Glottal area waveform (any unit).
    fps : float
        Sampling rate in frames per second (Hz).
    fmin, fmax : float
        Search range in Hz.

    Returns
    -------
    float
        f0 in Hz, or ``nan`` when the signal is constant or shows no period.

    Notes
    -----
    The unbiased autocorrelation is computed by FFT; the first local maximum above
    0.3 that reaches 80 % of the best peak inside lags ``[fps/fmax, fps/fmin]`` is
    taken (so sub-harmonic multiples of the period are not chosen) and refined by
    parabolic interpolation, then by the peaks at integer multiples of that lag (up
    to half the signal length) of the normalised cross-correlation of the overlapping
    parts (NCCF; Talkin 1995, "A robust algorithm for pitch tracking (RAPT)"), fitting
    ``lag_m = m * P`` through the origin. Autocorrelation pitch estimation: Rabiner (1977), IEEE
    Trans. ASSP 25(1):24-33.
    """
    x = np.asarray(gaw, dtype=float)
    x = np.asarray(gaw, dtype=float)
    if x.ndim != 1 or not np.all(np.isfinite(x)):
        return float("nan")
    x = x - x.mean()
    n = x.size
    if n < 4 or not np.any(x) or not (fps > 0):
        return float("nan")
    ac = _autocorrelation(x)
    lo = max(1, int(np.floor(fps / fmax)))
    hi = min(n - 2, int(np.ceil(fps / fmin)))
    if hi <= lo + 1:
        return float("nan")
    period = _first_peak_lag(ac, lo, hi)
    if period is None:
        return float("nan")
    return float(fps / _refined_period(x, period))


def _autocorrelation(x: np.ndarray) -> np.ndarray:
    """Unbiased normalised autocorrelation (n,) of the zero-mean signal ``x`` (n,), by FFT."""
    n = x.size
    nfft = 1 << int(np.ceil(np.log2(2 * n)))
    spec = np.fft.rfft(x, nfft)
    ac = np.fft.irfft(spec * np.conj(spec), nfft)[:n]
    ac = ac / ac[0]
    # unbiased correction so long lags are not penalised
    return ac * n / (n - np.arange(n))


def _first_peak_lag(ac: np.ndarray, lo: int, hi: int) -> float | None:
    """Lag (samples, fractional) of the first autocorrelation peak in ``[lo, hi]`` above 0.3 that reaches
    80 % of the best one, refined by a parabola through it and its neighbours; None without such a peak."""
    seg = ac[lo : hi + 1]
    # first local maximum above 0.3 (avoid picking sub-harmonic multiples)
    cand = [i for i in range(1, seg.size - 1) if seg[i] >= seg[i - 1] and seg[i] >= seg[i + 1] and seg[i] > 0.3]
    if not cand:
        return None
    best = max(seg[i] for i in cand)
    i = next(i for i in cand if seg[i] >= 0.8 * best)
    k = lo + i
    y0, y1, y2 = ac[k - 1], ac[k], ac[k + 1]
    denom = y0 - 2 * y1 + y2
    shift = 0.5 * (y0 - y2) / denom if denom != 0 else 0.0
    return k + shift


def _refined_period(x: np.ndarray, period: float) -> float:
    """The period (samples) refined by the peaks at its multiples (lags up to n/2).

    A least-squares line through the origin of ``lag_m = m * P`` reduces the interpolation error ~1/m
    (normalised cross-correlation of the overlapping parts, Talkin's NCCF: exact 1 at multiples of an
    integer period, and less biased than the global autocorrelation). ``period`` itself when no
    multiple has a clear peak."""
    n = x.size

    def nccf(lag: int) -> float:
        a, b = x[: n - lag], x[lag:]
        den = math.sqrt(float(np.dot(a, a)) * float(np.dot(b, b)))
        return float(np.dot(a, b)) / den if den > 0 else 0.0

    ms, lags = [], []
    half_w = max(1, int(round(0.15 * period)))
    m = 1
    while m * period + half_w + 1 < n // 2 or m == 1:
        c = int(round(m * period))
        if c - half_w < 1 or c + half_w + 1 >= n:
            break
        vals = [nccf(L) for L in range(c - half_w, c + half_w + 1)]
        jj = int(np.argmax(vals))
        j = c - half_w + jj
        if vals[jj] <= 0.3 or jj in (0, len(vals) - 1):
            break
        z0, z1, z2 = vals[jj - 1], vals[jj], vals[jj + 1]
        d = z0 - 2 * z1 + z2
        ms.append(float(m))
        lags.append(j + (0.5 * (z0 - z2) / d if d != 0 else 0.0))
        m += 1
    if not ms:
        return period
    ms_a, lags_a = np.asarray(ms), np.asarray(lags)
    return float(np.dot(ms_a, lags_a) / np.dot(ms_a, ms_a))


def as_gaw(gaw) -> np.ndarray:
    """``gaw`` as a float array (n,); ValueError unless it is one-dimensional and finite."""
    x = np.asarray(gaw, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"GAW must be 1D, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("GAW contains NaN or infinite values")
    return x


def cycle_boundaries(gaw: np.ndarray, fps: float, f0: float | None = None, tol: float = 0.01) -> np.ndarray:
    """Cycle boundaries at the area minima.

    Parameters
    ----------
    gaw : array_like, shape (n,)
        GAW (any unit).
    fps : float
        Frame rate (Hz).
    f0 : float, optional
        Fundamental frequency (Hz); estimated with :func:`estimate_f0` if omitted.
    tol : float
        Samples within ``tol * (max - min)`` of a window's minimum count as part of
        a flat minimum (a closed phase); the boundary is the middle of that run.

    Returns
    -------
    ndarray of int
        Sample indices ``b[0] < b[1] < ...``; cycle ``k`` is ``gaw[b[k]:b[k+1]]``.
        Empty if no period can be found.

    Notes
    -----
    The first boundary is the minimum of the first period; each next one is the
    minimum within ``[b + 0.5 P, b + 1.5 P]`` (``P = fps / f0`` samples), the
    usual minimum-to-minimum cycle definition for GAWs (e.g. Lohscheller et al.
    2013, "Phonovibrography", IEEE Trans. Med. Imaging).
    """
    x = as_gaw(gaw)
    if f0 is None:
        f0 = estimate_f0(x, fps)
    if not (f0 is not None and math.isfinite(f0) and f0 > 0):
        return np.zeros(0, dtype=int)
    period = fps / f0
    span = float(x.max() - x.min())
    if span <= 0 or x.size < 2 * period:
        return np.zeros(0, dtype=int)
    eps = tol * span

    def flat_min(lo: int, hi: int) -> int:
        # middle of the longest run of samples within eps of the window's minimum
        w = x[lo:hi]
        near = np.concatenate([[False], w <= w.min() + eps, [False]])
        edges = np.flatnonzero(np.diff(near.astype(np.int8)))
        starts, stops = edges[0::2], edges[1::2]
        j = int(np.argmax(stops - starts))
        return lo + (int(starts[j]) + int(stops[j]) - 1) // 2

    out = [flat_min(0, int(math.ceil(period)) + 1)]
    while True:
        lo = out[-1] + max(1, int(round(0.5 * period)))
        hi = out[-1] + int(round(1.5 * period)) + 1
        if hi > x.size:
            # accept a last boundary only if the whole search window fits
            break
        out.append(flat_min(lo, hi))
    return np.asarray(out, dtype=int)


def _crossing(x: np.ndarray, thr: float, start: int, stop: int, rising: bool) -> float:
    """Interpolated sample position where x crosses thr, scanning start..stop."""
    if rising:
        for i in range(start + 1, stop + 1):
            if x[i] > thr >= x[i - 1]:
                return i - 1 + (thr - x[i - 1]) / (x[i] - x[i - 1])
        return float(start)
    for i in range(stop, start, -1):
        if x[i - 1] > thr >= x[i]:
            return i - 1 + (x[i - 1] - thr) / (x[i - 1] - x[i])
    return float(stop)


def cycle_table(
    gaw: np.ndarray, fps: float, level: float = DEFAULT_LEVEL, boundaries: np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """Per-cycle timing and amplitude quantities.

    Parameters
    ----------
    gaw : array_like, shape (n,)
        GAW in mm^2.
    fps : float
        Frame rate (Hz).
    level : float
        Open-phase threshold as a fraction of the cycle's peak-to-peak amplitude.
    boundaries : array of int, optional
        From :func:`cycle_boundaries` (computed if omitted).

    Returns
    -------
    dict of ndarray, one entry per cycle
        ``start`` (sample), ``period`` (s), ``a_min``, ``a_max`` (mm^2),
        ``t_open``, ``t_opening``, ``t_closing`` (s), ``dmin`` (most negative
        dA/dt in the cycle, mm^2/s).
    """
    x = as_gaw(gaw)
    b = cycle_boundaries(x, fps) if boundaries is None else np.asarray(boundaries, dtype=int)
    dx = np.gradient(x) * fps
    keys = ("start", "period", "a_min", "a_max", "t_open", "t_opening", "t_closing", "dmin")
    rows = {k: [] for k in keys}
    for k in range(b.size - 1):
        s, e = int(b[k]), int(b[k + 1])
        c = x[s : e + 1]
        amin, amax = float(c.min()), float(c.max())
        p = s + int(np.argmax(c))
        if amax <= amin:
            continue
        thr = amin + level * (amax - amin)
        to = _crossing(x, thr, s, p, rising=True)
        tc = _crossing(x, thr, p, e, rising=False)
        rows["start"].append(s)
        rows["period"].append((e - s) / fps)
        rows["a_min"].append(amin)
        rows["a_max"].append(amax)
        rows["t_open"].append((tc - to) / fps)
        rows["t_opening"].append((p - to) / fps)
        rows["t_closing"].append((tc - p) / fps)
        rows["dmin"].append(float(dx[s : e + 1].min()))
    return {k: np.asarray(v, dtype=int if k == "start" else float) for k, v in rows.items()}
