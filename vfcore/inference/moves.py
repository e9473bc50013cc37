"""The Metropolis moves of the SMC sampler (:mod:`.smc`): proposals as small strategy objects, and their ratios.

Each generation the sampler fits a Gaussian to its reweighted particles (:func:`walk_cholesky`) and moves every
particle with one of two proposals, chosen per step (``kernel="rw"``, ``"independent"``, or ``"mixture"``,
which alternates them):

* :class:`RandomWalk`: ``theta' = theta + s L z`` with ``L L^T`` the particles' covariance and ``s`` the
  adapted scale. With ``coords="log"`` the walk runs in ``log theta`` (its covariance is the particles'
  there) and the Metropolis ratio gains the Jacobian ``sum log theta' - sum log theta``, because a uniform
  prior on ``theta`` has density ``prod theta`` in ``log theta``. With a symmetry (a
  :class:`.symmetry.ScaleGroup`: a direction along which the log-likelihood is exactly invariant) the
  covariance is projected off that direction and the sampler ends every step with an exact group move along
  it, which needs no simulation.
* :class:`Independence`: ``theta' = mu + c L z`` drawn from the fitted Gaussian itself (inflated by ``c``),
  whatever the current particle; the ratio gains the Hastings correction ``log q(theta) - log q(theta')``.

:func:`log_acceptance` is the log Metropolis ratio of a move targeting ``pi_phi``; with delayed acceptance
(Christen & Fox 2005) the first stage screens with a cheap log-likelihoods ``l~`` (:func:`log_acceptance` of
those) and the second accepts with :func:`delayed_log_acceptance`,
``min(1, exp(phi ((l' - l) - (l~' - l~))))``; the product of the two stages satisfies detailed balance for
``pi_phi`` exactly. The order of the floating-point operations here is the sampler's contract: a run is
reproducible bit for bit from its seed.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_triangular

__all__ = [
    "COORDS",
    "Independence",
    "RandomWalk",
    "check_moves",
    "delayed_log_acceptance",
    "log_acceptance",
    "moves_for",
    "walk_cholesky",
]

#: Coordinates of the random walk: the parameters themselves, or their logarithms.
COORDS = ("linear", "log")


class RandomWalk:
    """Gaussian random-walk proposal in ``coords`` ("linear" or "log")."""

    independent = False

    def __init__(self, coords: str = "linear"):
        self.coords = coords

    def propose(self, theta: np.ndarray, z: np.ndarray, scale: float, chol: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """Proposals (n, d) from the particles ``theta`` (n, d) and standard normal draws ``z`` (n, d)."""
        if self.coords == "log":
            return np.exp(np.log(theta) + scale * z @ chol.T)
        return theta + scale * z @ chol.T

    def log_jacobian(self, new: np.ndarray, old: np.ndarray) -> np.ndarray | None:
        """The prior's density change (k,) of a walk in ``log theta`` (None in linear coordinates)."""
        if self.coords == "log":
            return np.sum(np.log(new) - np.log(old), axis=1)
        return None


class Independence:
    """Independence proposal from the fitted Gaussian ``N(mu, c^2 L L^T)``, ``c`` = ``inflation``."""

    independent = True

    def __init__(self, inflation: float):
        self.inflation = float(inflation)

    def propose(self, theta: np.ndarray, z: np.ndarray, scale: float, chol: np.ndarray, mu: np.ndarray) -> np.ndarray:
        return mu + self.inflation * z @ chol.T

    def log_jacobian(self, new: np.ndarray, old: np.ndarray) -> None:
        return None

    def log_q(self, x: np.ndarray, mu: np.ndarray, chol: np.ndarray) -> np.ndarray:
        """Log density (k,) of the proposal at ``x`` (k, d), up to a constant (the box truncation cancels)."""
        c = self.inflation
        z = solve_triangular(chol, (x - mu).T, lower=True)
        return -0.5 * np.sum(z * z, axis=0) / (c * c)


def check_moves(kernel: str, coords: str | None, prior, reference, delayed: bool, symmetry) -> str:
    """Check that the move options go together; returns the walk's coordinates (``coords``, by default
    "log" with a symmetry and "linear" without)."""
    if delayed and (reference is not None or kernel != "rw"):
        raise ValueError("delayed acceptance is implemented for the random-walk kernel without a reference")
    if kernel not in ("rw", "independent", "mixture"):
        raise ValueError(f"kernel must be 'rw', 'independent' or 'mixture', got {kernel!r}")
    coords = coords if coords is not None else ("log" if symmetry is not None else "linear")
    if coords not in COORDS:
        raise ValueError(f"coords must be one of {COORDS}, got {coords!r}")
    if coords == "log" and (kernel != "rw" or reference is not None):
        raise ValueError("log coordinates are implemented for the random-walk kernel without a reference")
    if coords == "log" and np.any(prior.lo <= 0.0):
        raise ValueError("log coordinates need every prior lower bound > 0")
    if symmetry is not None and coords != "log":
        raise ValueError("moves along a symmetry need the random walk in log coordinates")
    if symmetry is not None and symmetry.prior.names != prior.names:
        raise ValueError("the symmetry's prior estimates other parameters than the sampler's")
    return coords


def moves_for(kernel: str, coords: str, inflation: float) -> tuple:
    """The proposals of even and odd move steps for ``kernel`` ("rw", "independent", "mixture")."""
    rw, ind = RandomWalk(coords), Independence(inflation)
    return {"rw": (rw, rw), "independent": (ind, ind), "mixture": (rw, ind)}[kernel]


def walk_cholesky(
    x: np.ndarray, w: np.ndarray, direction: np.ndarray | None, span: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean (d,) and Cholesky factor (d, d) of the particles ``x`` (n, d) with weights ``w`` (n,),
    in the walk's coordinates; the covariance is projected off the unit vector ``direction`` (a symmetry's
    orbit, sampled by group moves instead) and regularised by ``(1e-9 span)^2`` on its diagonal."""
    mu = w @ x
    dev = x - mu
    cov = (dev * w[:, None]).T @ dev
    if direction is not None:
        proj = np.eye(x.shape[1]) - np.outer(direction, direction)
        cov = proj @ cov @ proj
    cov += np.diag((1e-9 * span) ** 2)
    try:
        chol = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        chol = np.diag(np.sqrt(np.clip(np.diag(cov), 1e-30, None)))
    return mu, chol


def log_acceptance(
    phi: float, ll_new: np.ndarray, ll_old: np.ndarray, *, reference=None, log_q=None, log_jac=None
) -> np.ndarray:
    """Log Metropolis ratio (k,) of proposals with log-likelihoods ``ll_new`` against ``ll_old`` at
    temperature ``phi``; a failed proposal (non-finite) is refused, a finite one from a failed particle taken.

    ``reference``: the term ``(1 - phi) (log q_ref' - log q_ref)`` of a reference-started path; ``log_q``:
    ``(log q(theta), log q(theta'))`` of an independence proposal; ``log_jac``: a log walk's Jacobian."""
    with np.errstate(invalid="ignore"):
        log_alpha = np.where(np.isfinite(ll_new), phi * (ll_new - ll_old), -np.inf)
        if reference is not None:
            log_alpha = log_alpha + reference
        if log_q is not None:
            log_alpha = log_alpha + log_q[0] - log_q[1]
        if log_jac is not None:
            log_alpha = log_alpha + log_jac
    return np.where(np.isnan(log_alpha), np.inf, log_alpha)  # old -inf, new finite


def delayed_log_acceptance(
    phi: float, ll_new: np.ndarray, ll_old: np.ndarray, lc_new: np.ndarray, lc_old: np.ndarray
) -> np.ndarray:
    """Log ratio (k,) of delayed acceptance's second stage: the full model's ratio corrected by the cheap
    one (``lc_new``, ``lc_old``) that screened the proposals."""
    with np.errstate(invalid="ignore"):
        log_a2 = np.where(np.isfinite(ll_new), phi * ((ll_new - ll_old) - (lc_new - lc_old)), -np.inf)
    return np.where(np.isnan(log_a2), np.inf, log_a2)
