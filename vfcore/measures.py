"""Glottal-area-waveform (GAW) measures, each defined once here.

All functions take a 1D GAW ``gaw`` (area, normally mm^2) sampled at ``fps`` frames
per second and use numpy only. Sources and exact definitions are collected in
``docs/measures.md``; every function's docstring states its units and source.

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

Cycle measures are averaged (arithmetic mean) over all complete cycles.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = [
    "estimate_f0", "cycle_boundaries", "cycle_table", "open_quotient", "speed_quotient",
    "closing_quotient", "amplitude_quotient", "naq", "glottal_gap_index", "harmonic_amplitudes",
    "harmonic_richness_factor", "jitter", "shimmer", "subharmonic_to_harmonic_ratio",
    "gaw_measures", "DEFAULT_LEVEL",
]

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
    if x.ndim != 1 or not np.all(np.isfinite(x)):
        return float("nan")
    x = x - x.mean()
    n = x.size
    if n < 4 or not np.any(x) or not (fps > 0):
        return float("nan")
    nfft = 1 << int(np.ceil(np.log2(2 * n)))
    spec = np.fft.rfft(x, nfft)
    ac = np.fft.irfft(spec * np.conj(spec), nfft)[:n]
    ac = ac / ac[0]
    # unbiased correction so long lags are not penalised
    ac = ac * n / (n - np.arange(n))
    lo = max(1, int(np.floor(fps / fmax)))
    hi = min(n - 2, int(np.ceil(fps / fmin)))
    if hi <= lo + 1:
        return float("nan")
    seg = ac[lo:hi + 1]
    # first local maximum above 0.3 (avoid picking sub-harmonic multiples)
    cand = [i for i in range(1, seg.size - 1) if seg[i] >= seg[i - 1] and seg[i] >= seg[i + 1] and seg[i] > 0.3]
    if not cand:
        return float("nan")
    best = max(seg[i] for i in cand)
    i = next(i for i in cand if seg[i] >= 0.8 * best)
    k = lo + i
    y0, y1, y2 = ac[k - 1], ac[k], ac[k + 1]
    denom = y0 - 2 * y1 + y2
    shift = 0.5 * (y0 - y2) / denom if denom != 0 else 0.0
    period = k + shift
    # refine with the peaks at multiples of the period (lags up to n/2): a least-squares
    # line through the origin of lag_m = m * P reduces the interpolation error ~1/m
    # (normalised cross-correlation of the overlapping parts, Talkin's NCCF: exact 1
    # at multiples of an integer period, and less biased than the global autocorrelation)
    def nccf(lag: int) -> float:
        a, b = x[:n - lag], x[lag:]
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
        return float(fps / period)
    ms_a, lags_a = np.asarray(ms), np.asarray(lags)
    period = float(np.dot(ms_a, lags_a) / np.dot(ms_a, ms_a))
    return float(fps / period)


def _as_gaw(gaw) -> np.ndarray:
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
    x = _as_gaw(gaw)
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


def cycle_table(gaw: np.ndarray, fps: float, level: float = DEFAULT_LEVEL,
                boundaries: np.ndarray | None = None) -> dict[str, np.ndarray]:
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
    x = _as_gaw(gaw)
    b = cycle_boundaries(x, fps) if boundaries is None else np.asarray(boundaries, dtype=int)
    dx = np.gradient(x) * fps
    keys = ("start", "period", "a_min", "a_max", "t_open", "t_opening", "t_closing", "dmin")
    rows = {k: [] for k in keys}
    for k in range(b.size - 1):
        s, e = int(b[k]), int(b[k + 1])
        c = x[s:e + 1]
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
        rows["dmin"].append(float(dx[s:e + 1].min()))
    return {k: np.asarray(v, dtype=int if k == "start" else float) for k, v in rows.items()}


def _mean(v: np.ndarray) -> float:
    return float(np.mean(v)) if v.size else float("nan")


def open_quotient(gaw, fps, level: float = DEFAULT_LEVEL) -> float:
    """Open quotient OQ = T_o / T (dimensionless, mean over cycles).

    Source: Timcke, von Leden & Moore (1958), Arch. Otolaryngol. 68:1-19 (open
    quotient from high-speed films); GAW form as in Patel, Dubrovskiy & Döllinger
    (2014), J. Speech Lang. Hear. Res. 57:1151-1163 (note the threshold ``level``).
    """
    t = cycle_table(gaw, fps, level)
    return _mean(t["t_open"] / t["period"])


def speed_quotient(gaw, fps, level: float = DEFAULT_LEVEL) -> float:
    """Speed quotient SQ = T_op / T_cl (opening over closing time; dimensionless).

    Source: Timcke, von Leden & Moore (1958); Holmberg, Hillman & Perkell (1988),
    J. Acoust. Soc. Am. 84:511-529.
    """
    t = cycle_table(gaw, fps, level)
    ok = t["t_closing"] > 0
    return _mean(t["t_opening"][ok] / t["t_closing"][ok])


def closing_quotient(gaw, fps, level: float = DEFAULT_LEVEL) -> float:
    """Closing quotient ClQ = T_cl / T (dimensionless).

    Source: Holmberg, Hillman & Perkell (1988); Alku & Vilkman (1996), Folia
    Phoniatr. Logop. 48:240-254.
    """
    t = cycle_table(gaw, fps, level)
    return _mean(t["t_closing"] / t["period"])


def amplitude_quotient(gaw, fps) -> float:
    """Amplitude quotient AQ = (A_max - A_min) / |min dA/dt| in seconds.

    Source: Alku & Vilkman (1996), Folia Phoniatr. Logop. 48:240-254 (defined on
    the glottal flow; here applied to the area, whose derivative is taken by
    central differences, ``numpy.gradient``).
    """
    t = cycle_table(gaw, fps)
    ok = t["dmin"] < 0
    return _mean((t["a_max"][ok] - t["a_min"][ok]) / -t["dmin"][ok])


def naq(gaw, fps) -> float:
    """Normalised amplitude quotient NAQ = AQ / T (dimensionless, mean over cycles).

    Source: Alku, Bäckström & Vilkman (2002), J. Acoust. Soc. Am. 112:701-710.
    For a sinusoid NAQ = 1/pi; for a linear closing ramp of duration T_cl it equals
    T_cl / T.
    """
    t = cycle_table(gaw, fps)
    ok = t["dmin"] < 0
    return _mean((t["a_max"][ok] - t["a_min"][ok]) / -t["dmin"][ok] / t["period"][ok])


def glottal_gap_index(gaw, fps) -> float:
    """Glottal gap index GGI = A_min / A_max per cycle (dimensionless, 0 = complete closure).

    Source: Patel, Dubrovskiy & Döllinger (2014), J. Speech Lang. Hear. Res.
    57:1151-1163 (Glottis Analysis Tools parameter set).
    """
    t = cycle_table(gaw, fps)
    ok = t["a_max"] > 0
    return _mean(t["a_min"][ok] / t["a_max"][ok])


def _whole_cycle_segment(x: np.ndarray, b: np.ndarray, even: bool) -> tuple[np.ndarray, int]:
    m = b.size - 1
    if even and m % 2:
        m -= 1
    if m < 1:
        return x[:0], 0
    return x[b[0]:b[m]], m


def harmonic_amplitudes(gaw, fps, n_harmonics: int = 10) -> np.ndarray:
    """Amplitudes of harmonics 1..K of f0 (same unit as the GAW).

    The GAW is cut to a whole number ``m`` of cycles (boundary to boundary), so the
    k-th harmonic falls on DFT bin ``k*m``; the amplitude is ``2|X[k m]|/N``. ``K`` is
    limited by the Nyquist frequency. Returns an empty array if no cycle is found.
    """
    x = _as_gaw(gaw)
    b = cycle_boundaries(x, fps)
    seg, m = _whole_cycle_segment(x, b, even=False)
    if m == 0:
        return np.zeros(0)
    spec = np.fft.rfft(seg - seg.mean())
    kmax = min(n_harmonics, (spec.size - 1) // m)
    return 2.0 * np.abs(spec[m * np.arange(1, kmax + 1)]) / seg.size


def harmonic_richness_factor(gaw, fps, n_harmonics: int = 10) -> float:
    """Harmonic richness factor HRF = 10 log10(sum_{k>=2} H_k^2 / H_1^2) in dB.

    Source: Childers & Lee (1991), J. Acoust. Soc. Am. 90:2394-2410 (there on the
    glottal flow spectrum). ``H_k`` from :func:`harmonic_amplitudes`. A pure
    sinusoid gives ``-inf``.
    """
    h = harmonic_amplitudes(gaw, fps, n_harmonics)
    if h.size < 2 or h[0] <= 0:
        return float("nan")
    with np.errstate(divide="ignore"):
        return float(10.0 * np.log10(np.sum(h[1:] ** 2) / h[0] ** 2))


def jitter(gaw, fps) -> float:
    """Local period perturbation: mean |T_k - T_{k+1}| / mean T (dimensionless).

    Source: the "jitter (local)" definition of Boersma & Weenink, Praat manual,
    and Lieberman (1963), J. Acoust. Soc. Am. 35:344-353; periods are the
    minimum-to-minimum cycle lengths (sample resolution 1/fps).
    """
    t = cycle_table(gaw, fps)
    p = t["period"]
    if p.size < 2:
        return float("nan")
    return float(np.mean(np.abs(np.diff(p))) / np.mean(p))


def shimmer(gaw, fps) -> float:
    """Local amplitude perturbation: mean |a_k - a_{k+1}| / mean a (dimensionless).

    ``a_k = A_max - A_min`` of cycle k. Source: "shimmer (local)" of the Praat
    manual (Boersma & Weenink); amplitude perturbation of GAWs as in Patel et al.
    (2014).
    """
    t = cycle_table(gaw, fps)
    a = t["a_max"] - t["a_min"]
    if a.size < 2:
        return float("nan")
    return float(np.mean(np.abs(np.diff(a))) / np.mean(a))


def subharmonic_to_harmonic_ratio(gaw, fps, n_harmonics: int = 10) -> float:
    """Subharmonic-to-harmonic ratio SHR = sum_k S_{k-1/2} / sum_k H_k (dimensionless).

    ``H_k`` is the amplitude at ``k f0`` and ``S_{k-1/2}`` at ``(k - 1/2) f0``,
    k = 1..K, measured over an even number of whole cycles so both fall on DFT
    bins. 0 for a strictly periodic GAW; period doubling (alternating cycles)
    raises it. Source: Sun (2002), Proc. IEEE ICASSP, "Pitch determination and
    voice quality analysis using subharmonic-to-harmonic ratio" (there on a
    log spectrum; here on linear amplitudes).
    """
    x = _as_gaw(gaw)
    b = cycle_boundaries(x, fps)
    seg, m = _whole_cycle_segment(x, b, even=True)
    if m == 0:
        return float("nan")
    spec = np.abs(np.fft.rfft(seg - seg.mean()))
    kmax = min(n_harmonics, (spec.size - 1) // m)
    k = np.arange(1, kmax + 1)
    harm = spec[m * k].sum()
    sub = spec[m * k - m // 2].sum()
    return float(sub / harm) if harm > 0 else float("nan")


def gaw_measures(gaw, fps, level: float = DEFAULT_LEVEL, n_harmonics: int = 10) -> dict[str, float]:
    """All GAW measures of this module in one dictionary.

    Parameters
    ----------
    gaw : array_like, shape (n,)
        GAW in mm^2.
    fps : float
        Frame rate (Hz).
    level : float
        Open-phase threshold (fraction of peak-to-peak amplitude).
    n_harmonics : int
        Harmonics used by HRF and SHR.

    Returns
    -------
    dict
        ``f0_hz``, ``n_cycles``, ``period_s``, ``min_area_mm2``, ``max_area_mm2``,
        ``amplitude_mm2`` (mean peak-to-peak), ``open_quotient``, ``speed_quotient``,
        ``closing_quotient``, ``amplitude_quotient_s``, ``naq``, ``glottal_gap_index``,
        ``hrf_db``, ``jitter``, ``shimmer``, ``shr``. Values are ``nan`` when the
        GAW has fewer than two cycles.
    """
    x = _as_gaw(gaw)
    if not (fps > 0):
        raise ValueError(f"fps must be > 0, got {fps}")
    f0 = estimate_f0(x, fps)
    t = cycle_table(x, fps, level)
    per = t["period"]
    ok_cl = t["t_closing"] > 0
    ok_d = t["dmin"] < 0
    amp = t["a_max"] - t["a_min"]
    return {
        "f0_hz": f0,
        "n_cycles": int(per.size),
        "period_s": _mean(per),
        "min_area_mm2": float(x.min()) if x.size else float("nan"),
        "max_area_mm2": float(x.max()) if x.size else float("nan"),
        "amplitude_mm2": _mean(amp),
        "open_quotient": _mean(t["t_open"] / per) if per.size else float("nan"),
        "speed_quotient": _mean(t["t_opening"][ok_cl] / t["t_closing"][ok_cl]),
        "closing_quotient": _mean(t["t_closing"] / per) if per.size else float("nan"),
        "amplitude_quotient_s": _mean(amp[ok_d] / -t["dmin"][ok_d]),
        "naq": _mean(amp[ok_d] / -t["dmin"][ok_d] / per[ok_d]),
        "glottal_gap_index": _mean(t["a_min"][t["a_max"] > 0] / t["a_max"][t["a_max"] > 0]),
        "hrf_db": harmonic_richness_factor(x, fps, n_harmonics),
        "jitter": float(np.mean(np.abs(np.diff(per))) / np.mean(per)) if per.size > 1 else float("nan"),
        "shimmer": float(np.mean(np.abs(np.diff(amp))) / np.mean(amp)) if amp.size > 1 else float("nan"),
        "shr": subharmonic_to_harmonic_ratio(x, fps, n_harmonics),
    }
