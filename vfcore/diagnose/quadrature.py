"""Adaptive nested midpoint quadrature of a likelihood over a few bounded parameters.

Used to integrate an extension's *waveform-level* parameters (a leak area, a camera scale, a
frame-rate ratio, an exposure, a phase lag ...) out of the likelihood of each forward simulation:
they cost no simulation, so each draw of the material parameters carries the marginal likelihood

    L(theta) = (1 / V) * integral over the prior box of L(theta, phi) dphi        (uniform prior)

and the SMC only has to explore the material parameters (:ref:`diagnose`, "Integrated
parameters"). The evidence of the extended model is unchanged by this: it is the same integral,
done partly by quadrature and partly by the sampler.

Rule. The box is cut into ``n0`` cells per dimension and the likelihood is read at each cell's
centre (midpoint rule). Then, ``rounds`` times at most, the cells within one cell of the best
one (a 3 x 3 block in 2-D) are each split into ``split`` children per dimension, which replace
them. The refinement stops once the best cell's neighbours at its level are within ``tol`` nats
of it: for a Gaussian peak of width s read at spacing h the drop is h^2 / (2 s^2), so ``tol`` = 2
means h <= 2 s, where the midpoint rule's relative error is about exp(-2 pi^2 s^2 / h^2) < 1 %
(0.01 nats).
Peaks away from the best one stay at the coarse resolution (they are lower by construction).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp

__all__ = ["QuadResult", "integrate_loglik"]


@dataclass(frozen=True)
class QuadResult:
    """``log_mean``: log of the prior mean of the likelihood (log marginal likelihood);
    ``best``: the point of the largest likelihood read; ``best_ll`` its log-likelihood;
    ``mean`` / ``sd``: conditional posterior mean and sd of each parameter (midpoint weights);
    ``n_evals``: likelihood evaluations."""

    log_mean: float
    best: np.ndarray
    best_ll: float
    mean: np.ndarray
    sd: np.ndarray
    n_evals: int


def integrate_loglik(fn, lo, hi, *, n0=16, split: int = 3, rounds: int = 6, tol: float = 2.0) -> QuadResult:
    """Nested midpoint quadrature of ``exp(fn(phi))`` over the box ``[lo, hi]`` (see the module
    docstring). ``fn(points (m, d)) -> log-likelihoods (m,)``, ``-inf`` allowed. ``n0``: coarse
    cells per dimension (an int or one per dimension)."""
    lo = np.atleast_1d(np.asarray(lo, dtype=float))
    hi = np.atleast_1d(np.asarray(hi, dtype=float))
    d = lo.size
    if hi.size != d or not np.all(hi > lo):
        raise ValueError("integrate_loglik needs lo < hi in every dimension")
    n0 = np.broadcast_to(np.asarray(n0, dtype=int), (d,))
    if np.any(n0 < 1) or split < 2:
        raise ValueError("n0 must be >= 1 and split >= 2")
    h0 = (hi - lo) / n0
    # cells: integer index on their level's lattice, level, centre, log-likelihood
    axes = [np.arange(n) for n in n0]
    idx = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, d)
    level = np.zeros(idx.shape[0], dtype=int)
    centres = lo + (idx + 0.5) * h0
    ll = np.asarray(fn(centres), dtype=float).reshape(-1)
    n_evals = ll.size
    for _ in range(max(0, int(rounds))):
        if not np.any(np.isfinite(ll)):
            break
        b = int(np.nanargmax(np.where(np.isfinite(ll), ll, -np.inf)))
        lev = level[b]
        same = level == lev
        # neighbours of the best cell on its own lattice (Chebyshev distance 1)
        dist = np.max(np.abs(idx - idx[b]), axis=1)
        near = np.flatnonzero(same & (dist <= 1))
        nbrs = near[near != b]
        if nbrs.size and np.all(np.isfinite(ll[nbrs])) and np.max(ll[b] - ll[nbrs]) <= tol:
            break
        # split the best cell and its neighbours into split^d children each
        sub = np.stack(np.meshgrid(*[np.arange(split)] * d, indexing="ij"), axis=-1).reshape(-1, d)
        kids_idx = (idx[near][:, None, :] * split + sub[None, :, :]).reshape(-1, d)
        h = h0 / float(split) ** (lev + 1)
        kids_c = lo + (kids_idx + 0.5) * h
        kids_ll = np.asarray(fn(kids_c), dtype=float).reshape(-1)
        n_evals += kids_ll.size
        keep = np.ones(ll.size, dtype=bool)
        keep[near] = False
        idx = np.concatenate([idx[keep], kids_idx])
        level = np.concatenate([level[keep], np.full(kids_idx.shape[0], lev + 1)])
        centres = np.concatenate([centres[keep], kids_c])
        ll = np.concatenate([ll[keep], kids_ll])
    # midpoint rule: each cell weighs its share of the box's volume
    log_vol = -np.log(n0.astype(float)).sum() - d * level * math.log(split)
    terms = np.where(np.isfinite(ll), ll + log_vol, -np.inf)
    if not np.any(np.isfinite(terms)):
        nan = np.full(d, np.nan)
        return QuadResult(-math.inf, nan, -math.inf, nan, nan, n_evals)
    lm = float(logsumexp(terms))
    w = np.exp(terms - lm)
    mean = w @ centres
    var = w @ (centres - mean) ** 2
    # the spread within a cell: a cell of width h holds a uniform of variance h^2 / 12 at most
    hcell = h0[None, :] / float(split) ** level[:, None]
    var = var + w @ (hcell**2 / 12.0)
    b = int(np.argmax(terms - log_vol))
    return QuadResult(lm, centres[b].copy(), float(ll[b]), mean, np.sqrt(var), n_evals)
