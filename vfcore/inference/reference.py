"""Reference distributions for SMC started from a fitted posterior instead of the prior.

Likelihood-tempered SMC (:mod:`.smc`) starts from the prior and must find the likelihood's mode
itself. With a *reference* density ``q`` on the prior box the sampler can start from ``q`` and
temper along

    pi_phi(theta) ∝ q(theta)^(1 - phi) * (p(theta) L(theta))^phi,     0 = phi_0 < ... < phi_T = 1,

the generalized stepping-stone path of Fan, Wu, Chen, Kuo & Lewis (2011, Mol. Biol. Evol.
28:523, section "Generalized stepping-stone"); with ``q`` normalised, ``Z_0 = 1`` and the product
of the incremental weights estimates the evidence ``Z = ∫ p L`` itself, not a bound. The closer
``q`` is to the posterior, the fewer generations and the smaller the Monte Carlo error; where
``q`` misses posterior mass the estimate falls short, as a prior-started run that misses a mode
does.

:class:`GaussianReference` is a defensive mixture (Hesterberg 1995, Technometrics 37:185)

    q(theta) = (1 - eps) N_box(theta_g; mu, Sigma) U(theta_u) + eps p(theta),

a Gaussian truncated to the prior box in the dimensions ``g`` it covers (the material
parameters of a fitted posterior), uniform over the prior in the others (an extension's own
parameters), and with weight ``eps`` the whole prior, so that ``p L / q <= L / eps`` stays bounded
where the Gaussian has no mass. The truncated Gaussian's normaliser ``P(N(mu, Sigma) in box)`` is
a Monte Carlo fraction of ``n_mc`` draws (fixed seed, so the density is deterministic); its
relative variance ``(1 - P) / (P n_mc)`` is reported as ``log_norm_var`` and added to the
evidence's variance by the sampler.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.special import logsumexp

from .prior import Prior

__all__ = ["GaussianReference", "reference_from_posterior"]


class GaussianReference:
    """Defensive truncated-Gaussian reference on ``prior``'s box (module docstring).

    ``mean``, ``cov``: of the Gaussian over the first ``len(mean)`` dimensions of ``prior``
    (the remaining ones are uniform). ``eps``: the prior's weight in the mixture."""

    def __init__(self, prior: Prior, mean, cov, *, eps: float = 0.1, n_mc: int = 1 << 17, seed: int = 0):
        if not isinstance(prior, Prior):
            raise ValueError("reference needs a Prior")
        mean = np.atleast_1d(np.asarray(mean, dtype=float))
        cov = np.atleast_2d(np.asarray(cov, dtype=float))
        g = mean.size
        if not 1 <= g <= prior.ndim:
            raise ValueError(f"the Gaussian covers {g} dimensions; the prior has {prior.ndim}")
        if cov.shape != (g, g):
            raise ValueError(f"cov must be {g} x {g}, got {cov.shape}")
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
            raise ValueError("reference mean and covariance must be finite")
        if not 0.0 < eps < 1.0:
            raise ValueError(f"eps must lie in (0, 1), got {eps}")
        try:
            self._chol = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError as exc:
            raise ValueError("reference covariance is not positive definite") from exc
        self.prior, self.mean, self.cov, self.eps, self.g = prior, mean, cov, float(eps), g
        self._lo, self._hi = prior.lo[:g], prior.hi[:g]
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0x5EF,)))
        z = self._gauss(int(n_mc), rng)
        p_in = float(np.mean(self._inside(z)))
        if p_in <= 0.0:
            raise ValueError("the reference Gaussian has no mass inside the prior box")
        self.p_inside = p_in
        self.log_norm_var = (1.0 - p_in) / (p_in * int(n_mc))
        self._log_det = float(np.sum(np.log(np.diag(self._chol))))

    def _gauss(self, n: int, rng) -> np.ndarray:
        return self.mean + rng.standard_normal((n, self.g)) @ self._chol.T

    def _inside(self, x: np.ndarray) -> np.ndarray:
        return np.all((x >= self._lo) & (x <= self._hi), axis=1)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` draws from ``q`` (rejection for the truncation)."""
        out = self.prior.sample(n, rng)                    # uniform part, and the defensive draws
        gauss = rng.random(n) >= self.eps
        need = int(np.count_nonzero(gauss))
        got: list[np.ndarray] = []
        while need > 0:
            z = self._gauss(max(2 * need, 64), rng)
            z = z[self._inside(z)]
            got.append(z[:need])
            need -= got[-1].shape[0]
        if got:
            out[gauss, : self.g] = np.concatenate(got)
        return out

    def logpdf(self, thetas) -> np.ndarray:
        """Normalised log density of ``q`` (``-inf`` outside the prior box)."""
        x = np.atleast_2d(np.asarray(thetas, dtype=float))
        lp = self.prior.logpdf(x)
        from scipy.linalg import solve_triangular
        z = solve_triangular(self._chol, (x[:, : self.g] - self.mean).T, lower=True)
        lg = (-0.5 * np.sum(z * z, axis=0) - self._log_det - 0.5 * self.g * math.log(2 * math.pi)
              - math.log(self.p_inside))
        # the uniform dimensions of the Gaussian component: the prior's density over them
        lu = -float(np.sum(np.log(self.prior.width[self.g:])))
        out = logsumexp(np.stack([math.log1p(-self.eps) + lg + lu, math.log(self.eps) + lp]), axis=0)
        return np.where(np.isfinite(lp), out, -np.inf)


def reference_from_posterior(prior: Prior, post, *, inflate: float = 2.0, floor: float = 0.01,
                             eps: float = 0.1, seed: int = 0) -> GaussianReference:
    """A :class:`GaussianReference` on ``prior`` from a fitted posterior ``post`` whose parameters
    are the first ones of ``prior`` (a base fit, for an extended model's prior): weighted mean and
    covariance of ``post``'s particles, each sd floored at ``floor`` of the prior width (a
    collapsed ensemble still gives a proper Gaussian), the whole covariance scaled by
    ``inflate**2`` (the reference must be wider than the posterior it stands in for: the
    extended model's posterior is shifted and wider)."""
    x = np.asarray(post.samples, dtype=float)
    w = np.exp(np.asarray(post.log_weights, dtype=float) - logsumexp(post.log_weights))
    g = x.shape[1]
    if tuple(prior.names[:g]) != tuple(post.names):
        raise ValueError(f"the posterior's parameters {tuple(post.names)} are not the first ones of the prior "
                         f"{tuple(prior.names)}")
    mu = w @ x
    dev = x - mu
    cov = (dev * w[:, None]).T @ dev
    fl = (floor * prior.width[:g]) ** 2
    cov = cov + np.diag(fl)
    return GaussianReference(prior, mu, inflate ** 2 * cov, eps=eps, seed=seed)
