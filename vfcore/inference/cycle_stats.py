"""A phase-insensitive likelihood on summary statistics of the GAW (an option, measured; not a default).

Where the model's cycle is modulated or chaotic, the frame-by-frame Gaussian likelihood (Hadwin et al. 2019,
Eq. 15) compares one realisation of the trajectory with another: a perturbation of the parameters in the last
bit moves the waveform by whole millimetres squared a few cycles on, and the log-likelihood becomes a random
function of the parameters however continuous the forward model is. Wood (2010, Nature 466:1102) replaces such
a likelihood by a Gaussian one on statistics that describe the attractor rather than the path ("synthetic
likelihood"). The statistics here are continuous functions of the samples, with no cycle segmentation and no
discrete lag choice:

- the quantiles of the area over the compared window (``QUANTILES``): amplitude, closed phase and the shape of
  the area's distribution, blind to phase and to the order of the cycles;
- the autocovariance at lags 1 .. ``lag_periods`` observed periods, normalised by the observation's variance:
  the period, the cycle's shape and how regular it is.

Their sampling spread is estimated the way Wood's method needs it without repeated simulations of one parameter
vector: each record is cut into ``n_blocks`` blocks, the statistics of each block give a block-to-block variance,
and the variance of the whole-window statistic is taken as that over ``n_blocks`` (a block bootstrap; blocks of a
few cycles each, so that cycle-to-cycle variation and measurement noise both enter). The observation's and the
simulation's variances add. :ref:`validation-continuous-model`.
"""

from __future__ import annotations

import math

import numpy as np

QUANTILES = np.linspace(0.05, 0.95, 19)


def _autocov(x: np.ndarray, lags: int) -> np.ndarray:
    """Autocovariance of ``x`` (mean removed, divided by the length) at lags 1 .. ``lags``."""
    y = x - x.mean()
    n = y.size
    return np.array([np.dot(y[: n - k], y[k:]) / n for k in range(1, lags + 1)])


def statistics(gaw, n_lags: int, scale: float) -> np.ndarray:
    """Summary statistics of one record: the ``QUANTILES`` of the area (mm^2), then the autocovariance at lags
    1 .. ``n_lags`` frames divided by ``scale`` (mm^2; the observation's sd, so both parts are in mm^2)."""
    x = np.asarray(gaw, dtype=float)
    return np.concatenate([np.quantile(x, QUANTILES), _autocov(x, n_lags) / scale])


def block_statistics(gaw, n_lags: int, scale: float, n_blocks: int) -> tuple[np.ndarray, np.ndarray]:
    """Whole-record statistics and the variance of each, estimated from ``n_blocks`` equal blocks (their
    block-to-block variance over ``n_blocks``)."""
    x = np.asarray(gaw, dtype=float)
    whole = statistics(x, n_lags, scale)
    L = x.size // n_blocks
    per = np.array([statistics(x[b * L : (b + 1) * L], n_lags, scale) for b in range(n_blocks)])
    return whole, per.var(axis=0, ddof=1) / n_blocks


class CycleStatsLikelihood:
    """Synthetic Gaussian log-likelihood of a simulated GAW given an observed one (see the module docstring).

    obs : (n,) observed GAW at the camera rate, mm^2. fps : frame rate. sigma_e : frame noise sd of the
    observation, mm^2 (a floor for each statistic's sd: sigma_e / sqrt(n)). lag_periods, n_blocks : the
    autocovariance's reach in observed periods and the number of blocks of the variance estimate.
    """

    def __init__(self, obs, fps: float, sigma_e: float, lag_periods: float = 1.5, n_blocks: int = 4):
        from vfcore.cycles import estimate_f0

        self.obs = np.asarray(obs, dtype=float)
        f0 = estimate_f0(self.obs, fps)
        if not (f0 is not None and math.isfinite(f0)):
            raise ValueError("observed GAW shows no periodic oscillation (f0 could not be estimated)")
        self.n_lags = max(2, int(math.ceil(lag_periods * fps / f0)))
        if self.obs.size // n_blocks <= self.n_lags + 2:
            raise ValueError(
                f"observation of {self.obs.size} frames too short for {n_blocks} blocks of more than {self.n_lags} lags"
            )
        self.scale = max(float(self.obs.std()), 1e-12)
        self.n_blocks = int(n_blocks)
        self.floor = (sigma_e / math.sqrt(self.obs.size)) ** 2
        self.s_obs, self.v_obs = block_statistics(self.obs, self.n_lags, self.scale, self.n_blocks)

    def __call__(self, sim) -> float:
        """Log-likelihood of the simulated GAW ``sim`` (at least as long as the observation; its last ``n``
        frames, the settled end of the run, are compared). -inf when it is not finite or too short."""
        x = np.asarray(sim, dtype=float)
        n = self.obs.size
        if x.size < n or not np.all(np.isfinite(x[-n:])):
            return -math.inf
        s, v = block_statistics(x[-n:], self.n_lags, self.scale, self.n_blocks)
        var = self.v_obs + v + self.floor
        r = s - self.s_obs
        return float(-0.5 * np.sum(r * r / var + np.log(2.0 * math.pi * var)))
