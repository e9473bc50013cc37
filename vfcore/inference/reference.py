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

    ``mean``: of the Gaussian over the first ``len(mean)`` dimensions of ``prior`` (the remaining
    ones are uniform). ``cov``: one covariance ``(g, g)``, or several ``(k, g, g)`` about the same
    mean, mixed with equal weights (a narrow one that starts the sampler in a fitted mode and a
    wide one that lets it reach a shifted one). ``eps``: the prior's weight in the mixture."""

    def __init__(self, prior: Prior, mean, cov, *, eps: float = 0.1, n_mc: int = 1 << 17, seed: int = 0):
        if not isinstance(prior, Prior):
            raise ValueError("reference needs a Prior")
        mean = np.atleast_1d(np.asarray(mean, dtype=float))
        cov = np.asarray(cov, dtype=float)
        g = mean.size
        if not 1 <= g <= prior.ndim:
            raise ValueError(f"the Gaussian covers {g} dimensions; the prior has {prior.ndim}")
        covs = cov.reshape((1, g, g)) if cov.shape in ((g, g), (1, g, g)) else cov
        if covs.ndim != 3 or covs.shape[1:] != (g, g) or covs.shape[0] < 1:
            raise ValueError(f"cov must be {g} x {g} or k x {g} x {g}, got {cov.shape}")
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(covs))):
            raise ValueError("reference mean and covariance must be finite")
        if not 0.0 < eps < 1.0:
            raise ValueError(f"eps must lie in (0, 1), got {eps}")
        try:
            self._chols = [np.linalg.cholesky(c) for c in covs]
        except np.linalg.LinAlgError as exc:
            raise ValueError("reference covariance is not positive definite") from exc
        self.prior, self.mean, self.cov, self.eps, self.g = prior, mean, covs, float(eps), g
        self._lo, self._hi = prior.lo[:g], prior.hi[:g]
        self.p_inside, self.log_norm_var = [], 0.0
        for c, ch in enumerate(self._chols):
            rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0x5EF, c)))
            p_in = float(np.mean(self._inside(self._gauss(ch, int(n_mc), rng))))
            if p_in <= 0.0:
                raise ValueError("the reference Gaussian has no mass inside the prior box")
            self.p_inside.append(p_in)
            # delta method; the components' normalisers enter a mixture, bounded by the sum
            self.log_norm_var += (1.0 - p_in) / (p_in * int(n_mc))
        self._log_det = [float(np.sum(np.log(np.diag(ch)))) for ch in self._chols]

    def _gauss(self, chol, n: int, rng) -> np.ndarray:
        return self.mean + rng.standard_normal((n, self.g)) @ chol.T

    def _inside(self, x: np.ndarray) -> np.ndarray:
        return np.all((x >= self._lo) & (x <= self._hi), axis=1)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` draws from ``q`` (rejection for the truncation)."""
        out = self.prior.sample(n, rng)  # uniform part, and the defensive draws
        k = len(self._chols)
        comp = np.where(rng.random(n) >= self.eps, rng.integers(0, k, n), -1)
        for c, ch in enumerate(self._chols):
            rows = np.flatnonzero(comp == c)
            need, got = rows.size, []
            while need > 0:
                z = self._gauss(ch, max(2 * need, 64), rng)
                z = z[self._inside(z)]
                got.append(z[:need])
                need -= got[-1].shape[0]
            if rows.size:
                out[rows, : self.g] = np.concatenate(got)
        return out

    def logpdf(self, thetas) -> np.ndarray:
        """Normalised log density of ``q`` (``-inf`` outside the prior box)."""
        from scipy.linalg import solve_triangular

        x = np.atleast_2d(np.asarray(thetas, dtype=float))
        lp = self.prior.logpdf(x)
        k = len(self._chols)
        # the uniform dimensions of the Gaussian components: the prior's density over them
        lu = -float(np.sum(np.log(self.prior.width[self.g :])))
        terms = [math.log(self.eps) + lp]
        for ch, ld, p_in in zip(self._chols, self._log_det, self.p_inside):
            z = solve_triangular(ch, (x[:, : self.g] - self.mean).T, lower=True)
            lg = -0.5 * np.sum(z * z, axis=0) - ld - 0.5 * self.g * math.log(2 * math.pi) - math.log(p_in)
            terms.append(math.log1p(-self.eps) - math.log(k) + lg + lu)
        out = logsumexp(np.stack(terms), axis=0)
        return np.where(np.isfinite(lp), out, -np.inf)


def reference_from_posterior(
    prior: Prior,
    post,
    *,
    inflate: float = 2.0,
    floor: float = 0.01,
    wide: float | None = 0.1,
    eps: float = 0.1,
    seed: int = 0,
) -> GaussianReference:
    """A :class:`GaussianReference` on ``prior`` from a fitted posterior ``post`` whose parameters
    are the first ones of ``prior`` (a base fit, for an extended model's prior), about the
    weighted mean of ``post``'s particles:

    - *narrow*: their covariance, each sd floored at ``floor`` of the prior width (a collapsed
      ensemble still gives a proper Gaussian), scaled by ``inflate**2``; it starts the sampler in
      the fitted mode;
    - *wide* (unless ``wide`` is None): independent, sd ``wide`` of each prior width (or the narrow
      one's, if larger); it reaches a mode shifted by a few tenths of the prior (an effect the base
      fit absorbed by moving its material parameters), as a box of +-0.15 about the base fit does.

    The two are mixed with equal weights, and ``eps`` of the prior (module docstring)."""
    g = len(post.names)
    if tuple(prior.names[:g]) != tuple(post.names):
        raise ValueError(
            f"the posterior's parameters {tuple(post.names)} are not the first ones of the prior {tuple(prior.names)}"
        )
    mu = np.asarray(post.mean, dtype=float)
    cov = inflate**2 * (np.asarray(post.cov, dtype=float) + np.diag((floor * prior.width[:g]) ** 2))
    covs = [cov]
    if wide is not None:
        covs.append(np.diag(np.maximum((wide * prior.width[:g]) ** 2, np.diag(cov))))
    return GaussianReference(prior, mu, np.stack(covs), eps=eps, seed=seed)
