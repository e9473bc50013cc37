"""A linear-Gaussian toy problem with a closed-form posterior and evidence (for testing samplers).

In unit coordinates ``u = (theta - lo) / width`` of a box prior, ``y = A u + e`` with
``e ~ N(0, s^2 I)``. With the uniform prior on the box (density 1 in u) and the box wide
compared with the posterior, the posterior is ``N(m, C)`` with ``C = (A^T A / s^2)^-1``,
``m = C A^T y / s^2`` (Bishop 2006, Section 3.3), and the evidence is the Gaussian integral

    log Z = -(n - d)/2 log(2 pi) - n log s - 1/2 log det(A^T A / s^2) - |y - A m|^2 / (2 s^2),

up to the (checked, negligible) prior mass of the posterior outside the box.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from vfcore.inference.prior import Prior


class LinearGaussianToy:
    """Picklable ``thetas (k, d) -> loglik (k,)`` with exact ``mean``, ``cov``, ``log_evidence``."""

    def __init__(self, prior: Prior, n_obs: int = 6, noise: float = 0.05, seed: int = 0):
        d = prior.ndim
        rng = np.random.default_rng(seed)
        self.lo, self.width = prior.lo, prior.width
        self.A = rng.normal(size=(n_obs, d))
        self.noise = float(noise)
        self.u_true = rng.uniform(0.35, 0.65, size=d)
        self.y = self.A @ self.u_true + noise * rng.normal(size=n_obs)
        prec = self.A.T @ self.A / noise**2
        self.cov_u = np.linalg.inv(prec)
        self.mean_u = self.cov_u @ (self.A.T @ self.y / noise**2)
        self.mean = self.lo + self.width * self.mean_u
        self.cov = self.cov_u * np.outer(self.width, self.width)
        self.sd = np.sqrt(np.diag(self.cov))
        r = self.y - self.A @ self.mean_u
        self.log_evidence = float(
            -(n_obs - d) / 2 * math.log(2 * math.pi)
            - n_obs * math.log(noise)
            - 0.5 * np.linalg.slogdet(prec)[1]
            - 0.5 * r @ r / noise**2
        )
        sd_u = np.sqrt(np.diag(self.cov_u))
        # posterior mass outside the unit box (marginal bound): must be negligible for exactness
        self.truncation_mass = float(
            np.sum(stats.norm.cdf(-self.mean_u / sd_u) + stats.norm.sf((1 - self.mean_u) / sd_u))
        )

    def __call__(self, thetas) -> np.ndarray:
        u = (np.atleast_2d(np.asarray(thetas, dtype=float)) - self.lo) / self.width
        r = (self.y[None, :] - u @ self.A.T) / self.noise
        return -0.5 * np.sum(r * r, axis=1) - self.y.size * math.log(self.noise * math.sqrt(2 * math.pi))
