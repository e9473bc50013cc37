"""Adaptive likelihood tempering: the next temperature and the reweighting to it (:mod:`.smc`).

The next temperature ``phi'`` is found by bisection so that the effective sample size of the incremental
weights ``L^(phi' - phi)`` equals a target (adaptive tempering, Jasra et al. 2011; with equal weights this is
the conditional ESS of Zhou, Johansen & Aston 2016). The evidence increment is ``log mean_i L_i^(phi' - phi)``
(Del Moral, Doucet & Jasra 2006), its variance the delta-method one of the normalised weights.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp

from .diagnostics import ess_finite

__all__ = ["Reweighting", "next_temperature", "reweight"]


def next_temperature(loglik: np.ndarray, phi: float, target_ess: float, tol: float = 1e-10) -> float:
    """Largest ``phi' in (phi, 1]`` with ``ESS(L^(phi' - phi)) >= target_ess`` (bisection)."""
    ll = np.asarray(loglik, dtype=float)
    if ess_finite((1.0 - phi) * ll) >= target_ess:
        return 1.0
    lo, hi = 0.0, 1.0 - phi
    while hi - lo > tol * max(1.0, hi):
        mid = 0.5 * (lo + hi)
        if ess_finite(mid * ll) >= target_ess:
            lo = mid
        else:
            hi = mid
    # lo may be 0 if even an infinitesimal step fails (can't happen for finite ll); ensure progress
    return phi + max(lo, 1e-12)


@dataclass(frozen=True)
class Reweighting:
    """One tempering step: the new temperature, the normalised weights (m,), the log-evidence increment,
    its variance and the weights' ESS."""

    phi: float
    weights: np.ndarray
    log_evidence_increment: float
    log_evidence_var: float
    ess: float


def reweight(ll: np.ndarray, phi: float, ess_fraction: float) -> Reweighting:
    """Temper equally weighted particles with log-likelihoods ``ll`` (m,) (``-inf``: failed) from ``phi`` to
    the next temperature, whose ESS is ``ess_fraction`` of the finite ones."""
    n_fin = int(np.count_nonzero(np.isfinite(ll)))
    phi_new = next_temperature(ll, phi, ess_fraction * n_fin)
    dphi = phi_new - phi
    logw = np.where(np.isfinite(ll), dphi * ll, -np.inf)  # previous weights are equal (resampled)
    lse = logsumexp(logw)
    m = ll.size
    inc = float(lse - math.log(m))
    w = np.exp(logw - lse)
    sw2 = float(np.sum(w * w))
    return Reweighting(phi_new, w, inc, max(m / (m - 1) * (sw2 - 1.0 / m), 0.0), 1.0 / sw2)
