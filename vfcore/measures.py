"""Glottal-area-waveform measures, each defined once here.

All functions take a 1D GAW sampled at ``fps`` frames per second (area in mm^2).
"""
from __future__ import annotations

import numpy as np


def estimate_f0(gaw: np.ndarray, fps: float, fmin: float = 40.0, fmax: float = 600.0) -> float:
    """Fundamental frequency (Hz) from the normalised autocorrelation.

    The first autocorrelation peak inside [1/fmax, 1/fmin] is refined by parabolic
    interpolation. Returns ``nan`` when the signal is constant or shows no period.
    """
    x = np.asarray(gaw, dtype=float)
    x = x - x.mean()
    n = x.size
    if n < 4 or not np.any(x):
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
    return float(fps / (k + shift))
