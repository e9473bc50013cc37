"""Weight diagnostics: normalisation, effective sample size, PSIS Pareto-k, evidence, resampling.

References
----------
* Kong (1992) / Liu (2001): effective sample size ``ESS = 1 / sum w_i^2`` of normalised weights.
* Vehtari, Simpson, Gelman, Yao & Gabry (2024), "Pareto smoothed importance sampling",
  JMLR 25(72): the Pareto shape ``k`` of the upper weight tail; ``k > 0.7`` means the
  importance-sampling estimate is unreliable whatever the ESS says (computed with
  ``arviz.psislw``).
* Evidence ``Z = E_prior[L]`` estimated by the mean likelihood ratio; its Monte Carlo error
  on the log scale by the delta method, ``se(log Z) = sd(L) / (sqrt(N) mean(L))``.
* Systematic resampling: Kitagawa (1996); Douc, Cappe & Moulines (2005).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from scipy.special import logsumexp

#: Pareto-k above which importance-sampling estimates are unreliable (Vehtari et al. 2024).
PARETO_K_THRESHOLD = 0.7


class DegenerateEnsembleWarning(UserWarning):
    """The weighted ensemble is dominated by a few draws; estimates are not trustworthy."""


def normalize_log_weights(log_w) -> np.ndarray:
    """``log_w - logsumexp(log_w)``; ``-inf`` entries stay ``-inf``. Raises if all are ``-inf``."""
    lw = np.asarray(log_w, dtype=float).reshape(-1)
    lw = np.where(np.isnan(lw), -np.inf, lw)
    if not np.any(np.isfinite(lw)):
        raise RuntimeError("all weights are zero (every simulation failed or had zero likelihood)")
    return lw - logsumexp(lw)


def ess_from_logsums(lse_w: float, lse_w2: float) -> float:
    """Effective sample size ``(sum w)^2 / sum w^2`` from ``log sum w`` and ``log sum w^2``.

    The one ESS formula: :func:`ess`, :func:`ess_finite` and the worker's running ESS (which
    accumulates the two log-sums chunk by chunk) all end here."""
    return float(math.exp(2.0 * lse_w - lse_w2))


def ess(log_w) -> float:
    """Effective sample size ``(sum w)^2 / sum w^2`` of (unnormalised) log weights.

    The weights are normalised first (:func:`normalize_log_weights`: NaN counts as a zero weight,
    all-zero weights raise), so ``log sum w = 0``."""
    lw = normalize_log_weights(log_w)
    return ess_from_logsums(0.0, logsumexp(2.0 * lw))


def ess_finite(log_w) -> float:
    """Effective sample size of the finite entries of unnormalised log weights; 0 when none is
    finite (the tolerant form the SMC's tempering bisection needs: it never raises)."""
    lw = np.asarray(log_w)
    lw = lw[np.isfinite(lw)]
    if lw.size == 0:
        return 0.0
    return ess_from_logsums(logsumexp(lw), logsumexp(2.0 * lw))


def pareto_k(log_w) -> float:
    """PSIS Pareto shape estimate of the weight tail (ArviZ ``psislw``); NaN when undefined.

    Zero weights (failed simulations) are left out: they are not part of the tail.
    """
    lw = np.asarray(log_w, dtype=float).reshape(-1)
    lw = lw[np.isfinite(lw)]
    if lw.size < 10 or np.ptp(lw) == 0.0:
        return 0.0 if lw.size >= 10 else float("nan")
    import arviz as az  # local: arviz is heavy to import

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, k = az.psislw(lw - lw.max())
    return float(np.asarray(k))


def log_evidence_is(logliks) -> tuple[float, float]:
    """Log evidence ``log mean(L_i)`` from prior draws, and its Monte Carlo standard error.

    ``se = sqrt(N/(N-1) * (sum w_i^2 - 1/N))`` with ``w`` the normalised weights: the
    delta-method error of ``log Z`` from the sample variance of the likelihood ratios.
    Failed draws (``-inf``) count as zero likelihood.
    """
    ll = np.asarray(logliks, dtype=float).reshape(-1)
    ll = np.where(np.isnan(ll), -np.inf, ll)
    n = ll.size
    if n == 0 or not np.any(np.isfinite(ll)):
        return -math.inf, math.nan
    lse = logsumexp(ll)
    logz = float(lse - math.log(n))
    if n < 2:
        return logz, math.nan
    sw2 = float(np.exp(logsumexp(2.0 * (ll - lse))))
    return logz, float(math.sqrt(max(n / (n - 1) * (sw2 - 1.0 / n), 0.0)))


def systematic_resample(weights, m: int, rng: np.random.Generator) -> np.ndarray:
    """Systematic resampling: ``m`` indices, index i appearing floor or ceil of ``m w_i`` times.

    One uniform ``u ~ U[0, 1)``; the points ``(u + j) / m``, j = 0..m-1, are located in the
    cumulative weights. Returned indices are sorted.
    """
    w = np.asarray(weights, dtype=float).reshape(-1)
    if np.any(w < 0) or not np.all(np.isfinite(w)):
        raise ValueError("weights must be finite and non-negative")
    s = w.sum()
    if s <= 0:
        raise ValueError("weights sum to zero")
    cdf = np.cumsum(w / s)
    cdf[-1] = 1.0
    pts = (rng.random() + np.arange(int(m))) / int(m)
    idx = np.searchsorted(cdf, pts, side="right")
    return np.minimum(idx, w.size - 1)


def weighted_quantiles(x, weights, qs) -> np.ndarray:
    """Quantiles ``qs`` of the weighted sample ``x`` (n,) (interpolating the weighted CDF
    at the midpoints of each draw's mass, the rule of ``numpy``'s 'hazen' method)."""
    x = np.asarray(x, dtype=float)
    w = np.asarray(weights, dtype=float)
    keep = w > 0
    x, w = x[keep], w[keep]
    order = np.argsort(x, kind="stable")
    x, w = x[order], w[order] / w.sum()
    c = np.cumsum(w) - 0.5 * w
    return np.interp(np.asarray(qs, dtype=float), c, x)


def degeneracy_warnings(
    ess_value: float, n: int, k_hat: float, *, ess_min: float = 100.0, label: str = "importance sampling"
) -> list[str]:
    """Messages for a degenerate ensemble; each is also emitted as DegenerateEnsembleWarning."""
    msgs = []
    if ess_value < ess_min:
        msgs.append(
            f"DEGENERATE ENSEMBLE ({label}): effective sample size {ess_value:.1f} of {n} draws "
            f"is below {ess_min:g}; posterior mean/sd are dominated by a few draws and not "
            f"trustworthy. Use more draws, a larger sigma_e, or the SMC sampler."
        )
    if math.isfinite(k_hat) and k_hat > PARETO_K_THRESHOLD:
        msgs.append(
            f"UNRELIABLE WEIGHTS ({label}): Pareto k = {k_hat:.2f} > {PARETO_K_THRESHOLD} "
            f"(Vehtari et al. 2024); the weight distribution is too heavy-tailed for "
            f"{n} draws."
        )
    for m in msgs:
        warnings.warn(m, DegenerateEnsembleWarning, stacklevel=3)
    return msgs
