"""From simulated motion to what a camera sees, and alignment with a recording.

Hadwin et al. (2019), Section 4.1: glottal width W = 2 * min distance of the free
surface to the midline; area A = L * W with L = 17 mm; the simulated GAW is
downsampled to the camera rate and phase-aligned to the observation by
cross-correlating the first two cycles.
"""
from __future__ import annotations

import math

import numpy as np

from .measures import estimate_f0


def downsample(t: np.ndarray, y: np.ndarray, fps: float, t0: float) -> tuple[np.ndarray, np.ndarray]:
    """Sample ``y(t)`` at camera instants ``t0 + k/fps`` (linear interpolation).

    Returns (times relative to t0 in s, samples). ``y`` may be 1D (n,) or 2D (n, m).
    """
    t_end = t[-1]
    n = int(math.floor((t_end - t0) * fps + 1e-9)) + 1
    tc = t0 + np.arange(n) / fps
    if y.ndim == 1:
        return tc - t0, np.interp(tc, t, y)
    out = np.empty((n, y.shape[1]))
    for j in range(y.shape[1]):
        out[:, j] = np.interp(tc, t, y[:, j])
    return tc - t0, out


def alignment_window(obs: np.ndarray, fps: float, n_sim: int) -> tuple[int, int]:
    """Lag range and compared length for aligning a simulation to ``obs``.

    The length depends only on the observation and the simulation length, so every
    simulation in an ensemble is compared over the same number of frames (the
    likelihoods are then comparable).

    Returns (max_lag, n_compare) in frames.
    """
    f0 = estimate_f0(obs, fps)
    if not math.isfinite(f0):
        raise ValueError("observed GAW shows no periodic oscillation (f0 could not be estimated)")
    period = fps / f0
    max_lag = int(math.ceil(1.5 * period))
    n_cmp = min(obs.size, n_sim - max_lag)
    if n_cmp < 2 * period:
        raise ValueError(
            f"simulation ({n_sim} frames) too short to align an observation with period {period:.1f} frames")
    return max_lag, n_cmp


def align(sim: np.ndarray, obs: np.ndarray, fps: float, window: tuple[int, int] | None = None,
          sim_hr: np.ndarray | None = None, oversample: int | None = None,
          ) -> tuple[np.ndarray, np.ndarray, float]:
    """Phase-align a simulated GAW to an observed one.

    The first two observed cycles (the template) are cross-correlated with the simulation
    over lags 0..max_lag frames; the best lag picks the simulated segment.

    Without ``sim_hr`` the lag is a whole number of frames. With ``sim_hr`` (the same
    simulated GAW sampled ``oversample`` times faster from the same start, e.g.
    :attr:`vfcore.result.SimResult.gaw_hr`) the lag is refined below one frame: the
    correlation is evaluated on the fine grid within one frame of the best whole lag, its
    maximum is refined by a parabola through the three best fine lags, and the segment is
    read from ``sim_hr`` at the fractional lag by linear interpolation. The aligned segment
    then varies continuously with the model parameters; a whole-frame lag jumps by 1/fps
    (a twelfth of a cycle at 64 Hz and 2000 fps), which makes the likelihood of a narrow
    posterior discontinuous (docs/inference.md, "Sub-frame alignment").

    Returns (sim_segment, obs_segment, lag in frames), segments of length ``n_compare``.
    """
    sim = np.asarray(sim, dtype=float)
    obs = np.asarray(obs, dtype=float)
    max_lag, n_cmp = window if window is not None else alignment_window(obs, fps, sim.size)
    f0 = estimate_f0(obs, fps)
    n_tmpl = min(n_cmp, int(math.ceil(2 * fps / f0)) if math.isfinite(f0) else n_cmp)
    tmpl = obs[:n_tmpl] - obs[:n_tmpl].mean()
    best, best_lag = -np.inf, 0
    for lag in range(0, max_lag + 1):
        seg = sim[lag:lag + n_tmpl]
        c = float(np.dot(seg - seg.mean(), tmpl))
        if c > best:
            best, best_lag = c, lag
    if sim_hr is None:
        return sim[best_lag:best_lag + n_cmp], obs[:n_cmp], float(best_lag)
    q = int(oversample) if oversample is not None else 0
    hr = np.asarray(sim_hr, dtype=float)
    if q < 1 or hr.size < q * (sim.size - 1) + 1:
        raise ValueError(f"sim_hr ({hr.size} samples) does not hold {sim.size} frames at oversample {oversample!r}")
    # fine lags j/q frames within one frame of the best whole lag, kept inside the record
    j_lo = max(0, q * (best_lag - 1))
    j_hi = min(q * (best_lag + 1), q * (sim.size - 1 - (n_cmp - 1)))
    js = np.arange(j_lo, j_hi + 1)
    idx = js[:, None] + q * np.arange(n_tmpl)[None, :]
    segs = hr[idx]
    cs = (segs - segs.mean(axis=1, keepdims=True)) @ tmpl
    m = int(np.argmax(cs))
    frac = 0.0
    if 0 < m < cs.size - 1:
        c0, c1, c2 = cs[m - 1], cs[m], cs[m + 1]
        den = c0 - 2.0 * c1 + c2
        if den < 0:
            frac = float(np.clip(0.5 * (c0 - c2) / den, -0.5, 0.5))
    pos = js[m] + frac                       # fine-grid position of the aligned start
    x = pos + q * np.arange(n_cmp)
    i0 = np.minimum(np.floor(x).astype(np.int64), hr.size - 2)
    w = x - i0
    seg = (1.0 - w) * hr[i0] + w * hr[i0 + 1]
    return seg, obs[:n_cmp], pos / q
