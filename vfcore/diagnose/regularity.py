"""Is the fitted vibration regular? A sensitivity check of the waveform likelihood.

The diagnosis compares log-evidences of models whose likelihood reads the simulated GAW sample by
sample (vfcore.inference.problem). That is meaningful where the simulated limit cycle depends
smoothly on the parameters. At high subglottal pressure the fold model can vibrate irregularly
(period doubling, then chaos: Herzel, Berry, Titze & Saleh 1994, J. Speech Hear. Res. 37:1008;
Steinecke & Herzel 1995, J. Acoust. Soc. Am. 97:1874); then the waveform after the transient
depends on the parameters at every scale, the likelihood is a rough random function of them, and
a sampler's evidence is the luck of the points it happened to simulate. Measured on a concealed
recording at p_sub 1,714 Pa: the base fit's point gave log-likelihood -2,398; the same point
with every parameter changed by a relative 1e-9 gave -70,555 (:ref:`diagnose-pipeline`,
"Regularity").

:func:`sensitivity` re-simulates a fitted point and the same point with its free parameters
moved by a relative ``step`` (default 1e-6, far below any physical resolution) in ``n_dirs``
random directions. A regular limit cycle changes its log-likelihood by a first-order
``|grad| * step``: well under ``tol`` = 1 nat for any fit whose posterior sd exceeds 1e-4 of the
value (curvature ``1/sd^2``, distance ``step``). A change of more than ``tol`` flags the fit as
*irregular*.

That check sees chaos, not a likelihood that is smooth at 1e-6 and piecewise constant at 1e-4. A
vibration whose waveform does not repeat (a torus: the cycle's peaks modulated with a period of
several cycles) has a phase that no force restores, and each discrete event of the time-stepped
model (a node closing, opening or passing the separation point one step earlier or later) kicks
that phase by a finite amount. Measured on a six-parameter calibration twin (:ref:`inference`,
"Aperiodic vibration"): the likelihood is flat to 0.03 nats over a relative 1.5e-4 and then drops
by 68 nats, because in one cycle a node reopens for 1.5 ms during the closed phase; the peaks of
the cycles vary by 4 mm² and do not repeat within 8 cycles. A sampler cannot describe such a
likelihood with a mean and a spread. Two more measures flag it, both on the same point:

- ``aperiodicity``: how far the point's own waveform is from repeating after k = 1 ... ``max_period``
  cycles, in nats of the likelihood: ``n_compare * min_k mean((A(t) - A(t + k T))^2) / (2 sigma_e^2)``
  over the compared window, the lag refined around k / f0 (no simulation). A period-k limit cycle
  (period doubling included) scores near 0; a modulated or chaotic one scores what a shift of its
  modulation would cost.
- ``second_differences``: ``|l(theta (1 + s d)) + l(theta (1 - s d)) - 2 l(theta)|`` at a relative
  ``rough_step`` s (default 1e-4) in the same directions: a smooth likelihood gives ``(s / sd)^2``
  nats, far below ``rough_tol`` for any posterior sd above 1e-3 of the value; a step in between
  gives the step's height.

``rough`` is set where either exceeds its tolerance (``rough_tol``, ``aperiodic_tol``: 3 nats, the
gap the 3-run rule of :ref:`inference` reads as a difference); ``smooth`` is neither flag.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ..inference.problem import Problem, aligned_loglik

__all__ = ["Sensitivity", "aperiodicity", "rough_phrase", "sensitivity"]


@dataclass(frozen=True)
class Sensitivity:
    """``loglik``: at the point; ``changes``: ``|loglik(perturbed) - loglik|`` per direction
    (``inf`` where a perturbed run failed); ``irregular``: the largest change exceeds ``tol``."""

    step: float
    tol: float
    loglik: float
    changes: tuple[float, ...]
    irregular: bool
    n_simulations: int
    rough_step: float = 0.0
    second_differences: tuple[float, ...] = ()
    aperiodicity: float = 0.0
    rough: bool = False

    @property
    def max_change(self) -> float:
        return max(self.changes) if self.changes else 0.0

    @property
    def max_second_difference(self) -> float:
        return max(self.second_differences) if self.second_differences else 0.0

    @property
    def smooth(self) -> bool:
        """Neither flag: the likelihood is smooth at the fit at both scales and its waveform repeats."""
        return not (self.irregular or self.rough)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["changes"] = list(self.changes)
        d["second_differences"] = list(self.second_differences)
        d["max_change"] = self.max_change
        d["max_second_difference"] = self.max_second_difference
        d["smooth"] = self.smooth
        return d


def rough_phrase(d: dict) -> str:
    """What a rough verdict measured, in words, from :meth:`Sensitivity.to_dict` (an aperiodicity of NaN, no
    verdict, is left out)."""
    a = d.get("aperiodicity", math.nan)
    parts = (
        []
        if a is None or not math.isfinite(a)
        else [f"the waveform does not repeat within 4 cycles (a shift of its modulation costs {a:.3g} nats)"]
    )
    parts.append(
        f"a relative {d['rough_step']:g} change of the parameters has a second difference of "
        f"{d['max_second_difference']:.3g} nats"
    )
    return " or ".join(parts)


def aperiodicity(
    gaw_hr, f0: float, fps: float, oversample: int, n_compare: int, sigma_e: float, *, max_period: int = 4
) -> float:
    """The module docstring's ``aperiodicity`` (nats) of one oversampled simulated area ``gaw_hr``
    (``oversample`` samples per camera frame at ``fps``) with fundamental ``f0`` (Hz), read over the
    last ``n_compare`` frames before ``max_period`` cycles of the run's end (fewer where the run is
    shorter: the mean square is then read over what there is and scaled to ``n_compare`` frames);
    ``nan`` (no verdict) where less than two cycles are left to read or ``f0`` is not a frequency."""
    x = np.asarray(gaw_hr, dtype=float)
    if not (math.isfinite(f0) and f0 > 0):
        return math.nan
    period = fps * oversample / f0  # samples per cycle
    top = int(math.ceil(1.05 * max_period * period)) + 2
    n = min(int(n_compare) * int(oversample), x.size - top)
    if n < 2 * period:
        return math.nan
    base = x.size - n - top
    a = x[base : base + n]
    best = math.inf
    for k in range(1, int(max_period) + 1):
        lags = np.arange(max(1, int(0.95 * k * period)), int(math.ceil(1.05 * k * period)) + 1)
        mse = np.array([np.mean((a - x[base + lag : base + lag + n]) ** 2) for lag in lags])
        i = int(np.argmin(mse))
        m = float(mse[i])
        if 0 < i < mse.size - 1:
            # the minimum between samples: a parabola through the three samples around it
            c = mse[i - 1] - 2.0 * mse[i] + mse[i + 1]
            if c > 0:
                m = max(0.0, m - (mse[i + 1] - mse[i - 1]) ** 2 / (8.0 * c))
        best = min(best, m)
    return float(n_compare * best / (2.0 * sigma_e**2))


def sensitivity(
    problem: Problem,
    theta,
    *,
    step: float = 1e-6,
    n_dirs: int = 2,
    tol: float = 1.0,
    seed: int = 0,
    rough_step: float = 1e-4,
    rough_tol: float = 3.0,
    aperiodic_tol: float = 3.0,
    max_period: int = 4,
) -> Sensitivity:
    """The checks of the module docstring at the free parameters ``theta`` of ``problem.prior``:
    ``1 + 3 n_dirs`` simulations (``1 + n_dirs`` with ``rough_step=0``, which turns the second
    differences off)."""
    from ..batch import simulate_many
    from ..result import HR_OVERSAMPLE

    theta = np.asarray(theta, dtype=float).reshape(-1)
    prior = problem.prior
    if theta.size != prior.ndim:
        raise ValueError(f"theta has {theta.size} values; the prior has {prior.ndim} free parameters")
    if not (step > 0 and math.isfinite(step)) or int(n_dirs) < 1:
        raise ValueError("step must be > 0 and n_dirs >= 1")
    if not (rough_step >= 0 and math.isfinite(rough_step)):
        raise ValueError("rough_step must be >= 0 (0 = no second differences)")
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0x5E75,)))
    dirs = rng.choice([-1.0, 1.0], size=(int(n_dirs), theta.size))
    rows = [theta, *(theta * (1.0 + step * d) for d in dirs)]
    if rough_step > 0:
        rows += [theta * (1.0 + sgn * rough_step * d) for d in dirs for sgn in (1.0, -1.0)]
    pts = np.vstack(rows)
    res = simulate_many([prior.to_params(p) for p in pts], problem.config, block=pts.shape[0])

    def ll(r) -> float:
        if not r.ok:
            return -math.inf
        return float(aligned_loglik(np.asarray(r.gaw_hr, dtype=float), problem, r.params)[0])

    lls = [ll(r) for r in res]
    if not math.isfinite(lls[0]):
        raise RuntimeError("the fitted point itself failed to simulate")
    nd = int(n_dirs)
    changes = tuple(abs(v - lls[0]) if math.isfinite(v) else math.inf for v in lls[1 : 1 + nd])
    second = []
    for j in range(nd if rough_step > 0 else 0):
        up, down = lls[1 + nd + 2 * j], lls[2 + nd + 2 * j]
        second.append(abs(up + down - 2.0 * lls[0]) if math.isfinite(up) and math.isfinite(down) else math.inf)
    r0 = res[0]
    ap = aperiodicity(
        r0.gaw_hr, r0.f0, problem.fps, HR_OVERSAMPLE, problem.window[1], problem.sigma_e, max_period=max_period
    )
    rough = bool((second and max(second) > rough_tol) or ap > aperiodic_tol)  # nan: no verdict
    return Sensitivity(
        step=float(step),
        tol=float(tol),
        loglik=lls[0],
        changes=changes,
        irregular=bool(max(changes) > tol),
        n_simulations=len(res),
        rough_step=float(rough_step),
        second_differences=tuple(second),
        aperiodicity=float(ap),
        rough=rough,
    )
