"""Exact moves along the model's common-scale symmetry, at no simulation cost.

Multiplying E_body, E_cover, E_lig, p_sub, rho and eta by one factor ``c`` leaves the simulated glottal
area waveform unchanged (:ref:`inference-scale-the-common-scale-what-a`; tests/vfcore/test_scale_symmetry.py), so
when all six are estimated the GAW's log-likelihood is constant along every ray ``theta -> c theta``
through the origin of those six coordinates. A random walk has to crawl along that ridge, and the
posterior along it is only the prior's box (and whatever measurement anchors the scale). Both can be
handled exactly instead:

* the sampler's random walk runs in the logs of the parameters, where the rays are parallel lines
  along ``v`` (ones on the scaled coordinates), and its proposals are projected onto the complement
  of ``v``: it explores only the scale-invariant combinations (log-ratios), which the data determine;
* the log-scale ``t = log c`` is drawn from its exact conditional by a *group move* (Liu & Wu 1999,
  J Am Stat Assoc 94:1264; Liu & Sabatti 2000, J Am Stat Assoc 95:1013, generalised Gibbs sampler):
  for the multiplicative group acting on ``k`` coordinates, with Haar measure ``dc / c``, drawing
  ``c`` from ``p(c) ∝ pi(c theta) c^k dc / c`` leaves ``pi`` invariant. In ``t`` the density is
  ``exp(k t) pi(e^t theta)``: with a uniform prior it is ``exp(k t)`` truncated to the ray's part
  inside the prior box, times ``exp(phi m(e^t theta))`` where ``m`` is the part of the log-likelihood
  that is not invariant (a Gaussian measurement of p_sub or rho, ``Problem.measurements``).

No simulation is needed for the group move: the waveform, hence the GAW term of each particle's
log-likelihood, is unchanged, and the products scale in closed form (contact pressures and the
contact impulse by ``c``, the flow rate by ``sqrt(c)``, because the Bernoulli velocity is
``sqrt(2 p_sub / rho_air)`` and the air's density is not one of the six).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from .identify import SCALED
from .prior import Prior

#: Cells of the piecewise-constant proposal for the log-scale when a measurement shapes its conditional.
GRID_CELLS = 256
#: Independence Metropolis–Hastings steps per group move when a measurement shapes the conditional.
MH_STEPS = 3


def _truncated_exponential(rate: float, lo: np.ndarray, hi: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Inverse-CDF draws of ``t`` with density ``∝ exp(rate t)`` on ``[lo, hi]`` (elementwise), ``u`` uniform."""
    width = hi - lo
    x = rate * width
    # t = lo + log(1 + u (e^x - 1)) / rate, written to keep its digits for small and large x
    big = x > 30.0
    t = np.empty_like(lo)
    with np.errstate(over="ignore", divide="ignore"):
        small_t = lo + np.log1p(u * np.expm1(x)) / rate
        # for large x: t = hi + log(u + (1 - u) e^-x) / rate
        large_t = hi + np.log(u + (1.0 - u) * np.exp(-x)) / rate
    t[:] = np.where(big, large_t, small_t)
    return np.clip(t, lo, hi)


@dataclass(frozen=True)
class ScaleGroup:
    """The multiplicative group acting on the coordinates ``idx`` of a free-parameter vector.

    Parameters
    ----------
    prior : Prior
        The sampler's prior (uniform on its box; every bound of the scaled coordinates > 0).
    idx : ndarray of int
        The coordinates that scale together.
    offset : callable, optional
        ``thetas (n, d) -> (n,)``: the part of the log-likelihood that is not invariant under the
        group (the measurements' log density); None when the log-likelihood is invariant.
    """

    prior: Prior
    idx: np.ndarray
    offset: Callable[[np.ndarray], np.ndarray] | None = None

    def __post_init__(self) -> None:
        idx = np.asarray(self.idx, dtype=int).reshape(-1)
        if idx.size < 2 or np.unique(idx).size != idx.size or idx.min() < 0 or idx.max() >= self.prior.ndim:
            raise ValueError(f"idx must be >= 2 distinct coordinates of the {self.prior.ndim}-vector, got {idx}")
        if np.any(self.prior.lo[idx] <= 0.0):
            raise ValueError("the scaled coordinates need prior lower bounds > 0")
        object.__setattr__(self, "idx", idx)

    @property
    def direction(self) -> np.ndarray:
        """Unit vector (d,) of the group's orbits in log coordinates."""
        v = np.zeros(self.prior.ndim)
        v[self.idx] = 1.0 / math.sqrt(self.idx.size)
        return v

    def ray(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The log-scale interval ``[t_lo, t_hi]`` (each (n,)) that keeps ``e^t theta`` inside the box."""
        th = np.atleast_2d(theta)[:, self.idx]
        lo, hi = self.prior.lo[self.idx], self.prior.hi[self.idx]
        return np.max(np.log(lo / th), axis=1), np.min(np.log(hi / th), axis=1)

    def scaled(self, theta: np.ndarray, t: np.ndarray) -> np.ndarray:
        out = np.array(theta, dtype=float, copy=True)
        out[:, self.idx] *= np.exp(t)[:, None]
        return out

    def move(
        self, theta: np.ndarray, phi: float, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One group move of every row of ``theta`` (n, d) under the tempered target ``p L^phi``.

        Returns ``(theta_new, t, d_offset)``: the moved particles, the log-scale each was moved by
        (0 where it stayed) and the change of the non-invariant log-likelihood term (add it to each
        particle's log-likelihood; zeros without an offset)."""
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        n = theta.shape[0]
        k = float(self.idx.size)
        t_lo, t_hi = self.ray(theta)
        t_lo, t_hi = np.minimum(t_lo, 0.0), np.maximum(t_hi, 0.0)  # a particle on the box's face stays inside
        if self.offset is None or phi == 0.0:
            t = _truncated_exponential(k, t_lo, t_hi, rng.random(n))
            return self.scaled(theta, t), t, np.zeros(n)
        return self._move_measured(theta, phi, rng, k, t_lo, t_hi)

    def n_distinct(self, theta: np.ndarray) -> int:
        """Distinct particles of ``theta`` (n, d) counted off the orbits (in log coordinates projected off
        :attr:`direction`): group moves make every particle's position along its orbit distinct without
        telling the data anything."""
        v = self.direction
        x = np.log(theta)
        x = x - np.outer(x @ v, v)
        return int(np.unique(np.round(x, 10), axis=0).shape[0])

    def _move_measured(self, theta, phi, rng, k, t_lo, t_hi):
        """Independence Metropolis–Hastings on ``t`` with a piecewise-constant proposal fitted to the
        conditional on a grid: exact for any proposal, and accepting nearly always because the
        proposal follows the conditional closely."""
        n, g = theta.shape[0], GRID_CELLS
        frac = (np.arange(g) + 0.5) / g
        mids = t_lo[:, None] + frac[None, :] * (t_hi - t_lo)[:, None]  # (n, g)
        grid = np.repeat(theta, g, axis=0)
        grid[:, self.idx] *= np.exp(mids.reshape(-1))[:, None]
        log_f_mid = k * mids + phi * self.offset(grid).reshape(n, g)
        log_f_mid = np.where(np.isfinite(log_f_mid), log_f_mid, -np.inf)
        m = np.max(log_f_mid, axis=1, keepdims=True)
        cell_w = np.exp(log_f_mid - m)
        cell_w /= cell_w.sum(axis=1, keepdims=True)
        width = np.maximum(t_hi - t_lo, 1e-300) / g

        def log_q(t):
            j = np.clip(((t - t_lo) / width).astype(int), 0, g - 1)
            return np.log(cell_w[np.arange(n), j]) - np.log(width)

        def log_f(th, t):
            return k * t + phi * self.offset(self.scaled(th, t))

        t = np.zeros(n)
        lf = log_f(theta, t)
        lq = log_q(t)
        off0 = self.offset(theta)
        for _ in range(MH_STEPS):
            cum = np.cumsum(cell_w, axis=1)
            j = np.minimum((cum < rng.random(n)[:, None]).sum(axis=1), g - 1)
            t_new = t_lo + (j + rng.random(n)) * width
            lf_new, lq_new = log_f(theta, t_new), log_q(t_new)
            with np.errstate(invalid="ignore"):
                log_a = (lf_new - lf) + (lq - lq_new)
            acc = np.log(rng.random(n)) < np.where(np.isnan(log_a), -np.inf, log_a)
            t = np.where(acc, t_new, t)
            lf = np.where(acc, lf_new, lf)
            lq = np.where(acc, lq_new, lq)
        new = self.scaled(theta, t)
        return new, t, self.offset(new) - off0


def rescale_products(ev, t: np.ndarray, d_offset: np.ndarray):
    """The Evaluation of particles moved by ``e^t`` along the scale: the same waveforms, the
    log-likelihood changed by ``d_offset``, contact pressures and impulse times ``c = e^t`` and the
    flow rate times ``sqrt(c)`` (module docstring)."""
    c = np.exp(np.asarray(t, dtype=float))
    kw = {"loglik": np.where(np.isfinite(ev.loglik), ev.loglik + d_offset, ev.loglik)}
    for name in ("mean_contact", "max_contact", "contact_impulse", "contact_pressure_in_contact"):
        a = getattr(ev, name)
        if a is not None:
            kw[name] = a * c
    if ev.mean_flow is not None:
        kw["mean_flow"] = ev.mean_flow * np.sqrt(c)
    return replace(ev, **kw)


def move_particles(group: ScaleGroup, theta: np.ndarray, ev, phi: float, rng: np.random.Generator):
    """One exact group move of every particle ``theta`` (n, d) whose log-likelihood in ``ev`` is finite
    (a failed one stays). Returns ``(theta, ev, d)``: the moved particles, their evaluation with the
    products rescaled (:func:`rescale_products`) and the change (n,) of the log-likelihood."""
    fin = np.isfinite(ev.loglik)
    th, t, d = group.move(theta, phi, rng)
    t = np.where(fin, t, 0.0)
    d = np.where(fin, d, 0.0)
    return np.where(fin[:, None], th, theta), rescale_products(ev, t, d), d


def scale_group(problem) -> ScaleGroup | None:
    """The scale group of an FE ``Problem`` whose estimated parameters include all six scaled ones
    (else None: a fixed one anchors the scale and there is no exact symmetry). Its offset is the
    measurements' log density."""
    prior = problem.prior
    names = prior.names
    if getattr(problem, "model", "fe") != "fe" or not all(n in names for n in SCALED):
        return None
    idx = np.array([names.index(n) for n in SCALED])
    offset = None
    if problem.measurements:
        from .problem import measurement_terms

        meas = dict(problem.measurements)
        cols = {n: names.index(n) for n in meas}  # measured names are estimated ones

        def offset(thetas: np.ndarray) -> np.ndarray:
            th = np.atleast_2d(thetas)
            return measurement_terms({n: th[:, j] for n, j in cols.items()}, meas)

    return ScaleGroup(prior, idx, offset)


__all__ = ["GRID_CELLS", "MH_STEPS", "ScaleGroup", "rescale_products", "scale_group"]
