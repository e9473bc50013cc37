"""Is the fitted vibration regular? A sensitivity check of the waveform likelihood.

The diagnosis compares log-evidences of models whose likelihood reads the simulated GAW sample by
sample (vfcore.inference.problem). That is meaningful where the simulated limit cycle depends
smoothly on the parameters. At high subglottal pressure the fold model can vibrate irregularly
(period doubling, then chaos: Herzel, Berry, Titze & Saleh 1994, J. Speech Hear. Res. 37:1008;
Steinecke & Herzel 1995, J. Acoust. Soc. Am. 97:1874); then the waveform after the transient
depends on the parameters at every scale, the likelihood is a rough random function of them, and
a sampler's evidence is the luck of the points it happened to simulate. Measured on concealed
case 06 of seed 4 (p_sub 1,714 Pa): the base fit's point gave log-likelihood -2,398; the same point
with every parameter changed by a relative 1e-9 gave -70,555 (docs/diagnose.md section 4,
"Regularity").

:func:`sensitivity` re-simulates a fitted point and the same point with its free parameters
moved by a relative ``step`` (default 1e-6, far below any physical resolution) in ``n_dirs``
random directions. A regular limit cycle changes its log-likelihood by a first-order
``|grad| * step``: well under ``tol`` = 1 nat for any fit whose posterior sd exceeds 1e-4 of the
value (curvature ``1/sd^2``, distance ``step``). A change of more than ``tol`` flags the fit as
*irregular*.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ..inference.problem import Problem, aligned_loglik

__all__ = ["Sensitivity", "sensitivity"]


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

    @property
    def max_change(self) -> float:
        return max(self.changes) if self.changes else 0.0

    def to_dict(self) -> dict:
        d = asdict(self)
        d["changes"] = list(self.changes)
        d["max_change"] = self.max_change
        return d


def sensitivity(problem: Problem, theta, *, step: float = 1e-6, n_dirs: int = 2, tol: float = 1.0,
                seed: int = 0) -> Sensitivity:
    """The check of the module docstring at the free parameters ``theta`` of ``problem.prior``."""
    from ..batch import simulate_many
    theta = np.asarray(theta, dtype=float).reshape(-1)
    prior = problem.prior
    if theta.size != prior.ndim:
        raise ValueError(f"theta has {theta.size} values; the prior has {prior.ndim} free parameters")
    if not (step > 0 and math.isfinite(step)) or int(n_dirs) < 1:
        raise ValueError("step must be > 0 and n_dirs >= 1")
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0x5E75,)))
    dirs = rng.choice([-1.0, 1.0], size=(int(n_dirs), theta.size))
    pts = np.vstack([theta, theta * (1.0 + step * dirs)])
    res = simulate_many([prior.to_params(p) for p in pts], problem.config, block=pts.shape[0])

    def ll(r) -> float:
        if not r.ok:
            return -math.inf
        return float(aligned_loglik(np.asarray(r.gaw_hr, dtype=float), problem, r.params)[0])

    lls = [ll(r) for r in res]
    if not math.isfinite(lls[0]):
        raise RuntimeError("the fitted point itself failed to simulate")
    changes = tuple(abs(v - lls[0]) if math.isfinite(v) else math.inf for v in lls[1:])
    return Sensitivity(step=float(step), tol=float(tol), loglik=lls[0], changes=changes,
                       irregular=bool(max(changes) > tol), n_simulations=len(res))
