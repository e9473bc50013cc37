"""Scoring simulations against a :class:`~vfcore.inference.problem.Problem`: run the forward model over the
rows of a batch, align each result to the observation, and collect log-likelihoods (Eq. 15), predictions,
flow and contact into an :class:`~vfcore.inference.evaluation.Evaluation`.

Every function takes the problem as an argument and reads only its public methods (``align``, ``loglik``)
and fields, so this module sits above the problem without importing it.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from .evaluation import Evaluation


def cycle_means(r) -> tuple[float, float, float]:
    """(mean flow m^3/s, mean contact Pa, max contact Pa) of one successful simulation."""
    c = r.cycles
    if c is not None and np.size(c.period) > 0:
        return (
            float(np.mean(c.mean_flow)),
            float(np.mean(c.mean_contact_pressure)),
            float(np.max(c.max_contact_pressure)),
        )
    flow = float(np.mean(r.flow)) if np.size(r.flow) else math.nan
    cp = np.asarray(r.contact_pressure)
    if cp.ndim == 2 and cp.size:
        spatial_max = cp.max(axis=1)
        return flow, float(spatial_max.mean()), float(spatial_max.max())
    return flow, math.nan, math.nan


def contact_means(r) -> tuple[float, float]:
    """(contact impulse per cycle N s/m, pressure in contact Pa), means over the cycles of one
    successful simulation; nan when it has no cycles or no per-step contact summaries."""
    c = r.cycles
    if c is None or np.size(c.period) == 0 or np.size(c.contact_impulse) != np.size(c.period):
        return math.nan, math.nan
    return float(np.mean(c.contact_impulse)), float(np.mean(c.contact_pressure_in_contact))


def _simulate_rows(thetas, problem, simulate_fn: Callable | None, block: int):
    """One SimResult (or the exception it raised) per row of ``thetas``.

    With the default forward model, rows whose parameters are valid are simulated in
    lock-step blocks (:func:`vfcore.batch.simulate_many`: the same arithmetic per sample as
    ``simulate``, up to floating-point summation order, about 1.9x the throughput at block 16).
    """
    out: list = [None] * thetas.shape[0]
    params = []
    for i, th in enumerate(thetas):
        try:
            params.append((i, problem.prior.to_params(th)))
        except Exception as exc:  # noqa: BLE001 - reported per draw
            out[i] = exc
    if simulate_fn is None and block > 1 and len(params) > 1:
        from vfcore.batch import simulate_many

        try:
            res = simulate_many([p for _, p in params], problem.config, block=block)
        except NotImplementedError:
            res = None
        if res is not None:
            for (i, _), r in zip(params, res):
                out[i] = r
            return out
    if simulate_fn is None:
        from vfcore.forward import simulate as simulate_fn  # lazy: keeps this module importable alone
    for i, p in params:
        try:
            out[i] = simulate_fn(p, problem.config)
        except Exception as exc:  # noqa: BLE001
            out[i] = exc
    return out


def evaluate(thetas, problem, simulate_fn: Callable | None = None, block: int | None = None) -> Evaluation:
    """Run the forward model at each row of ``thetas`` (k, d) and score it against the data.

    A pure function of its inputs (the unit of work of one worker chunk). A simulation
    that fails (``ok`` False, an exception, non-finite output, or too short to align)
    gets log-likelihood ``-inf`` and a NaN prediction row; its reason is in ``messages``.
    ``simulate_fn(params, config) -> SimResult`` defaults to the FE model, run ``block``
    rows at a time in lock-step (default :data:`vfcore.batch.LOCKSTEP_WIDTH`; ``block=1``: one
    :func:`vfcore.forward.simulate` per row).
    """
    if block is None:
        from vfcore.batch import LOCKSTEP_WIDTH as block
    thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
    return score_results(_simulate_rows(thetas, problem, simulate_fn, block), problem)


def aligned_loglik(hr: np.ndarray, problem, params=None) -> tuple[float, np.ndarray]:
    """Log-likelihood (Eq. 15) and aligned camera-rate segment of one oversampled simulated area
    ``hr`` (``HR_OVERSAMPLE`` samples per frame) against ``problem``'s observation: the profile /
    xcorr alignment of ``problem.alignment`` over ``problem.window``. For the many waveforms one
    simulation yields (screening, integrated extension parameters). ``params``: the draw's
    parameters, for the measurements' term (:meth:`Problem.loglik`)."""
    from vfcore.result import HR_OVERSAMPLE

    seg = problem.align(hr[::HR_OVERSAMPLE], sim_hr=hr, oversample=HR_OVERSAMPLE)
    return problem.loglik(seg, params), seg


def aligned_logliks(hrs, problem) -> tuple[np.ndarray, np.ndarray]:
    """:func:`aligned_loglik` (without the measurements' term) of several oversampled simulated areas of
    one length, the rows of ``hrs``, aligned together (:meth:`Problem.align_many`); each row's value and
    segment are the same bytes as its own call's. Returns (log-likelihoods (m,), segments (m, n_compare))."""
    from vfcore.result import HR_OVERSAMPLE

    segs = problem.align_many(hrs, HR_OVERSAMPLE)
    return np.array([problem.loglik(seg) for seg in segs], dtype=float), segs


def score_results(results, problem, observe: Callable | None = None) -> Evaluation:
    """Score simulation results (SimResults, or the exceptions their runs raised) against
    ``problem``'s observation: alignment, Eq. 15 log-likelihood (plus the measurements' term at each
    result's parameters), predictions, flow and contact.

    ``observe(i, gaw_hr) -> gaw_hr``, when given, maps result ``i``'s oversampled area to what the
    camera records before alignment (the observation-level model extensions of
    :mod:`vfcore.diagnose.fit`); the camera-rate series is then read from its output.
    """
    from vfcore.result import HR_OVERSAMPLE

    k = len(results)
    max_lag, n_cmp = problem.window
    loglik = np.full(k, -np.inf)
    ok = np.zeros(k, dtype=bool)
    gaw = np.full((k, n_cmp), np.nan, dtype=np.float32)
    flow = np.full(k, np.nan)
    cmean = np.full(k, np.nan)
    cmax = np.full(k, np.nan)
    cimp = np.full(k, np.nan)
    cin = np.full(k, np.nan)
    messages = []
    for i, r in enumerate(results):
        try:
            if isinstance(r, BaseException):
                raise r
            if not r.ok:
                raise RuntimeError(r.message or "simulation failed")
            hr = getattr(r, "gaw_hr", None)
            has_hr = hr is not None and np.size(hr) > 1
            if observe is not None:
                if not has_hr:
                    raise RuntimeError("the result has no oversampled GAW to observe")
                hr = observe(i, np.asarray(hr, dtype=float))
                if not np.all(np.isfinite(hr)):
                    raise RuntimeError("observed GAW is not finite")
                sim = hr[::HR_OVERSAMPLE]
            else:
                sim = np.asarray(r.gaw, dtype=float)
            if sim.size < max_lag + n_cmp:
                raise RuntimeError(f"simulation yielded {sim.size} frames, {max_lag + n_cmp} needed to align")
            if not np.all(np.isfinite(sim)):
                raise RuntimeError("simulated GAW is not finite")
            seg = problem.align(sim, sim_hr=hr, oversample=HR_OVERSAMPLE) if has_hr else problem.align(sim)
            ll = problem.loglik(seg, r.params)
        except Exception as exc:  # noqa: BLE001 - one bad draw must not sink an ensemble; counted
            messages.append(f"{i}: {type(exc).__name__}: {exc}")
            continue
        loglik[i] = ll
        ok[i] = True
        gaw[i] = seg
        flow[i], cmean[i], cmax[i] = cycle_means(r)
        cimp[i], cin[i] = contact_means(r)
    return Evaluation(
        loglik=loglik,
        ok=ok,
        gaw=gaw,
        mean_flow=flow,
        mean_contact=cmean,
        max_contact=cmax,
        messages=tuple(messages),
        contact_impulse=cimp,
        contact_pressure_in_contact=cin,
    )


class ProblemEvaluator:
    """Picklable batch function ``thetas -> Evaluation`` for a Problem (what ``map`` ships)."""

    def __init__(self, problem, simulate_fn: Callable | None = None):
        self.problem = problem
        self.simulate_fn = simulate_fn

    def __call__(self, thetas) -> Evaluation:
        return evaluate(thetas, self.problem, self.simulate_fn)
