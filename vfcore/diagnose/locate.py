"""Locate a model/recording mismatch: residuals folded on the glottal cycle, and measure p-values.

Phase classification (of the *observed* GAW ``y``)
---------------------------------------------------
Cycles are those of :func:`vfcore.measures.cycle_boundaries` (minimum to minimum). In cycle
``k`` (samples ``b[k] <= i < b[k+1]``) let ``A_min``, ``A_max`` be the cycle's extreme areas,
``D = A_max - A_min`` and ``i_p`` the sample of ``A_max`` (first one). With ``level`` (default
:data:`vfcore.measures.DEFAULT_LEVEL` = 0.05, the open-phase threshold of ``measures``) and
``peak_level`` (default 0.9):

- **closed**  : ``y[i] <= A_min + level * D``  (the measures' closed phase; with incomplete
  closure this is the "most-closed" phase, the area floor);
- **peak**    : ``y[i] >= A_min + peak_level * D``  (top 10 % of the excursion);
- **opening** : neither closed nor peak, and ``i < i_p``;
- **closing** : neither closed nor peak, and ``i > i_p``.

Samples outside complete cycles (before ``b[0]`` or at/after ``b[-1]``) are labelled
``none`` and are left out of the per-phase statistics (they are still in ``total_rms``).

Residual ``r = y - mean_k(pred_k)`` (observation minus posterior-predictive mean). Per phase
we report the RMS of ``r`` over the phase's samples and the *share of residual energy*
``sum_phase r^2 / sum_classified r^2`` (shares over the four phases sum to 1), and the
*time share* (fraction of classified samples in the phase), so ``energy_share / time_share``
> 1 marks a phase where the residual is concentrated. The *dominant phase* is the phase of largest
concentration when that concentration is at least ``min_concentration`` (default 1.25);
otherwise the residual is spread over the cycle and ``dominant_phase`` is :data:`SPREAD`
("whole cycle"). A constant offset (a leak the model lacks, a scale error of the area floor) has
concentration 1 in every phase, and naming the phase that happens to lead by a few per cent
would point the reader at a place in the cycle the mismatch does not prefer. The folded profile averages ``r`` in
``n_bins`` bins of normalised cycle phase ``(i - b[k]) / (b[k+1] - b[k])``.

Posterior-predictive p-values (Gelman, Meng & Stern 1996, Statistica Sinica 6:733-807)
------------------------------------------------------------------------------------
For a measure ``T`` (from :func:`vfcore.measures.gaw_measures`) and predictive GAWs
``pred_1..pred_k``: the mid-p value ``p = (#{j : T(pred_j) > T(y)} + #{j : T(pred_j) = T(y)} / 2)
/ k'`` over the ``k'`` draws where ``T`` is finite (ties, as a glottal gap index of exactly 0 in
the recording and every draw, count half: Lancaster 1961, JASA 56:223), and the two-sided
``p2 = min(1, 2 min(p, 1 - p))``. ``p`` near 0 means the recording's value is above every
predicted one; near 1, below.

Replicated recordings need the recording's noise: the model's noise-free GAWs get N(0, s^2)
noise (``sigma_e``). Noise-sensitive measures (min area, glottal gap index, amplitude, jitter,
shimmer, SHR) are decided by ``s``: with the likelihood's nominal sigma_e = 1 mm^2 on recordings
whose noise was 0.5 mm^2, the glottal gap index, the min area and the amplitude were flagged
(p2 < 0.05) in 40 of 40 recordings of the model itself, the amplitude quotient and SHR in 13
(``tests/vfcore/diagnose/test_diagnose.py``); with ``s`` estimated, each measure in 1-6 of 40 (mean 7.5 %
against the nominal 5 %), while a 1.5 mm^2 leak still flags the gap index and the min area in
20 of 20 and a 15 % scale error the amplitude in 20 of 20.
``sigma_e="estimate"`` takes ``s`` from the recording (:func:`noise_sd`): the robust scale of the
second differences of the residual against the mean prediction, divided by sqrt(6) (the
pseudo-residuals of Gasser, Sroka & Jennen-Steinmetz 1986, Biometrika 73:625; the MAD scaled by
1.4826 for a normal scale). Differencing removes the slow part of the residual, so a systematic
misfit of the model (the mismatch itself) hardly enters ``s``: the residual RMS would count it as
noise and flag the min area of a fit whose only error is its amplitude. It assumes white noise;
noise smoothed by the camera or by video compression is underestimated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..gawio import noise_sd as recording_noise_sd
from ..measures import DEFAULT_LEVEL, cycle_boundaries, gaw_measures

PHASES = ("closed", "opening", "peak", "closing")
SPREAD = "whole cycle"  # dominant_phase when no phase holds a concentrated residual
MIN_CONCENTRATION = 1.25
_CODE = {p: i for i, p in enumerate(PHASES)}  # none = -1

#: Measures tested by default (keys of ``gaw_measures``), the issue's list.
DEFAULT_MEASURES = (
    "f0_hz",
    "open_quotient",
    "speed_quotient",
    "closing_quotient",
    "amplitude_quotient_s",
    "naq",
    "glottal_gap_index",
    "min_area_mm2",
    "amplitude_mm2",
    "hrf_db",
    "shr",
    "jitter",
    "shimmer",
)


def phase_labels(
    obs, fps: float, level: float = DEFAULT_LEVEL, peak_level: float = 0.9, boundaries=None
) -> tuple[np.ndarray, np.ndarray]:
    """Phase code per sample of the observed GAW (see module docstring).

    Returns (codes (n,) int: 0 closed, 1 opening, 2 peak, 3 closing, -1 none; boundaries).
    """
    y = np.asarray(obs, dtype=float)
    if not 0.0 <= level < peak_level <= 1.0:
        raise ValueError(f"need 0 <= level < peak_level <= 1, got {level}, {peak_level}")
    b = cycle_boundaries(y, fps) if boundaries is None else np.asarray(boundaries, dtype=int)
    codes = np.full(y.size, -1, dtype=int)
    for k in range(b.size - 1):
        s, e = int(b[k]), int(b[k + 1])
        c = y[s:e]
        amin, amax = float(c.min()), float(c.max())
        d = amax - amin
        idx = np.arange(s, e)
        if d <= 0:
            codes[s:e] = _CODE["closed"]
            continue
        ip = s + int(np.argmax(c))
        lab = np.where(idx < ip, _CODE["opening"], _CODE["closing"])
        lab[c >= amin + peak_level * d] = _CODE["peak"]
        lab[c <= amin + level * d] = _CODE["closed"]
        codes[s:e] = lab
    return codes, b


@dataclass
class LocateReport:
    """Where in the glottal cycle the residual lives."""

    phase_rms: dict[str, float]
    energy_share: dict[str, float]
    time_share: dict[str, float]
    n_samples: dict[str, int]
    total_rms: float
    dominant_phase: str | None  # a phase of PHASES, SPREAD, or None when the residual is 0
    fold_phase: np.ndarray = field(repr=False)  # (n_bins,) bin centres in [0, 1)
    fold_mean: np.ndarray = field(repr=False)  # (n_bins,) mean residual per bin (nan if empty)
    residual: np.ndarray = field(repr=False)  # (n,)
    codes: np.ndarray = field(repr=False)  # (n,)
    boundaries: np.ndarray = field(repr=False)

    def concentration(self) -> dict[str, float]:
        """energy_share / time_share per phase (> 1: residual concentrated there)."""
        return {p: (self.energy_share[p] / self.time_share[p] if self.time_share[p] > 0 else math.nan) for p in PHASES}


def _mean_prediction(pred) -> np.ndarray:
    p = np.asarray(pred, dtype=float)
    if p.ndim == 2:
        p = p[np.all(np.isfinite(p), axis=1)]
        if p.shape[0] == 0:
            raise ValueError("no finite predictive draw")
        return p.mean(axis=0)
    if p.ndim != 1:
        raise ValueError(f"prediction must be (n,) or (k, n), got shape {p.shape}")
    return p


def locate(
    obs,
    pred,
    fps: float,
    *,
    level: float = DEFAULT_LEVEL,
    peak_level: float = 0.9,
    n_bins: int | None = None,
    min_concentration: float = MIN_CONCENTRATION,
) -> LocateReport:
    """Phase-folded residual analysis of ``obs`` (n,) against ``pred`` ((k, n) ensemble or (n,) mean).

    ``n_bins`` of the folded profile defaults to min(50, shortest cycle in samples), so every bin
    holds samples of every cycle."""
    y = np.asarray(obs, dtype=float)
    mu = _mean_prediction(pred)
    n = min(y.size, mu.size)
    y, mu = y[:n], mu[:n]
    r = y - mu
    codes, b = phase_labels(y, fps, level, peak_level)
    cls = codes >= 0
    e_tot = float(np.sum(r[cls] ** 2))
    n_cls = int(cls.sum())
    rms, share, tshare, cnt = {}, {}, {}, {}
    for p in PHASES:
        m = codes == _CODE[p]
        cnt[p] = int(m.sum())
        rms[p] = float(np.sqrt(np.mean(r[m] ** 2))) if m.any() else math.nan
        share[p] = float(np.sum(r[m] ** 2) / e_tot) if e_tot > 0 else math.nan
        tshare[p] = cnt[p] / n_cls if n_cls else math.nan
    dom = None
    if e_tot > 0:
        conc = {p: share[p] / tshare[p] for p in PHASES if tshare[p] > 0}
        dom = max(conc, key=conc.get) if conc else None
        if dom is not None and conc[dom] < min_concentration:
            dom = SPREAD
    # fold
    if n_bins is None:
        n_bins = int(min(50, np.diff(b).min())) if b.size > 1 else 1
    edges = np.linspace(0.0, 1.0, n_bins + 1)
    acc, num = np.zeros(n_bins), np.zeros(n_bins)
    for k in range(b.size - 1):
        s, e = int(b[k]), int(b[k + 1])
        ph = (np.arange(s, e) - s) / (e - s)
        j = np.minimum((ph * n_bins).astype(int), n_bins - 1)
        np.add.at(acc, j, r[s:e])
        np.add.at(num, j, 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        fold = np.where(num > 0, acc / np.maximum(num, 1), np.nan)
    return LocateReport(
        phase_rms=rms,
        energy_share=share,
        time_share=tshare,
        n_samples=cnt,
        total_rms=float(np.sqrt(np.mean(r**2))) if n else math.nan,
        dominant_phase=dom,
        fold_phase=0.5 * (edges[:-1] + edges[1:]),
        fold_mean=fold,
        residual=r,
        codes=codes,
        boundaries=b,
    )


@dataclass(frozen=True)
class MeasureCheck:
    name: str
    observed: float
    pred_mean: float
    pred_sd: float
    p_upper: float  # fraction of draws with T(pred) >= T(obs)
    p_two_sided: float
    n_draws: int  # draws with a finite value


def _ppp(obs_val: float, draws: np.ndarray) -> tuple[float, float]:
    d = draws[np.isfinite(draws)]
    if not math.isfinite(obs_val) or d.size == 0:
        return math.nan, math.nan
    p = float(np.mean(d > obs_val) + 0.5 * np.mean(d == obs_val))  # mid-p: ties count half
    return p, min(1.0, 2.0 * min(p, 1.0 - p))


def noise_sd(obs, pred) -> float:
    """Noise sd of a recording from its residual against the mean prediction (module docstring):
    ``1.4826 MAD(diff(r, 2)) / sqrt(6)``; 0 for fewer than 5 samples."""
    y = np.asarray(obs, dtype=float)
    mu = _mean_prediction(pred)
    n = min(y.size, mu.size)
    if n < 5:
        return 0.0
    return recording_noise_sd(y[:n] - mu[:n])


def predictive_measures(pred, fps: float, names=DEFAULT_MEASURES) -> dict[str, np.ndarray]:
    """Each measure of every predictive draw, (k,) per name (nan where it is undefined)."""
    p = np.atleast_2d(np.asarray(pred, dtype=float))
    out = {n: np.full(p.shape[0], math.nan) for n in names}
    for j, g in enumerate(p):
        if not np.all(np.isfinite(g)):
            continue
        m = gaw_measures(g, fps)
        for n in names:
            out[n][j] = float(m[n])
    return out


def measure_pvalues(
    pred, obs, fps: float, names=DEFAULT_MEASURES, *, sigma_e: float | str | None = None, seed: int = 0
) -> dict[str, MeasureCheck]:
    """Posterior-predictive p-value of each GAW measure (see module docstring).

    ``pred`` (k, n) predictive GAWs, ``obs`` (n,). With ``sigma_e`` each draw gets N(0, sigma_e^2)
    noise (deterministic in ``seed``) so the reference distribution is that of a new recording;
    ``sigma_e="estimate"``: the recording's own noise sd (:func:`noise_sd`); ``None``: noise-free.
    """
    p = np.atleast_2d(np.asarray(pred, dtype=float))
    if isinstance(sigma_e, str):
        if sigma_e != "estimate":
            raise ValueError(f"sigma_e must be a number, None or 'estimate', got {sigma_e!r}")
        sigma_e = noise_sd(obs, p)
    elif sigma_e is not None and not (math.isfinite(float(sigma_e)) and float(sigma_e) >= 0):
        raise ValueError(f"sigma_e must be a finite number >= 0 (mm^2), got {sigma_e!r}")
    if sigma_e is not None and sigma_e > 0:
        p = p + sigma_e * np.random.default_rng(seed).standard_normal(p.shape)
    mobs = gaw_measures(np.asarray(obs, dtype=float), fps)
    draws = predictive_measures(p, fps, names)
    out = {}
    for n in names:
        d = draws[n]
        f = d[np.isfinite(d)]
        pu, p2 = _ppp(float(mobs[n]), d)
        out[n] = MeasureCheck(
            n,
            float(mobs[n]),
            float(f.mean()) if f.size else math.nan,
            float(f.std(ddof=1)) if f.size > 1 else math.nan,
            pu,
            p2,
            int(f.size),
        )
    return out


def from_posterior(post, *, sigma_e: float | str | None = "estimate", names=DEFAULT_MEASURES, **kw):
    """(LocateReport, p-values) from a fitted :class:`vfcore.inference.Posterior` with predictions
    (the replicated recordings' noise estimated from the recording unless ``sigma_e`` is given)."""
    rp = post.resampled_predictive()
    if rp is None or rp.gaw is None or post.obs_gaw is None or post.fps is None:
        raise ValueError("posterior carries no predictive GAWs / observation")
    g = post.recorded_gaws()
    obs = np.asarray(post.obs_gaw, dtype=float)[: g.shape[1]]
    return locate(obs, g, post.fps, **kw), measure_pvalues(g, obs, post.fps, names, sigma_e=sigma_e)
