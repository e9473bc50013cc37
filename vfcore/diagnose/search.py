"""Window-continuation mode search, and the SMC fit started from its optimum.

Why (:ref:`diagnose-search-continuation-search`): on a recording whose vibration drifts
or is irregular, the waveform log-likelihood over the whole window is a rough function of the
material parameters: a relative change of 1e-4 in a modulus moves the phase of the late cycles by
a large fraction of a period. A tempered SMC of a few dozen particles then collapses on the best
spike it happened to draw, which is often not the mode (on 9 missed concealed-effect
recordings, at the true materials the right entry left about the noise in 7, its SMC fit 1.3-2.6
times more).

The remedy used for fitting oscillators by least squares is continuation in the length of the
data (the multiple-shooting argument of Bock 1981; Voss, Timmer & Kurths 2004, Int. J.
Bifurcation Chaos 14:1905): fit the first ``cycles0`` cycles, where a 1 % f0 error costs little
phase, then double the window and polish from the previous optimum, until the whole recording is
fitted; the polish steps shrink with the window, as the ridge does. Starts: the best points of a
scrambled Sobol design on the first window, and any given points (a fit's best particle).

:func:`continuation_search` returns the best point and its whole-window log-likelihood;
:func:`continued_fit` then runs the ordinary SMC (:func:`vfcore.inference.smc.smc`) from a narrow
Gaussian reference about that point, so what the ranking compares is again a log-evidence of the
model with its Monte Carlo error (the generalized stepping-stone path of
:mod:`vfcore.inference.reference`), not an optimum.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from ..inference.importance import map_evaluate
from ..inference.problem import Evaluation, Problem, ProblemEvaluator
from ..measures import estimate_f0

__all__ = [
    "CONTINUATION",
    "SearchResult",
    "model_evaluator",
    "model_prior",
    "windows",
    "window_problems",
    "continuation_search",
    "continuation_searches",
    "continued_fit",
    "continued_fits",
]

#: default search: Sobol design points, starts kept from it, first window in cycles, Nelder-Mead
#: evaluations on window k (``maxfev0 + maxfev_step * k``) and its initial simplex step in unit
#: coordinates (``max(step0 / step_ratio**k, step_min)``). Why these (:ref:`diagnose-pipeline`,
#: "Continuation search"): on a concealed leak a start reached 0.52 mm^2 (truth 0.48) in 270
#: simulations with them, and stopped at 1.11 with 30 evaluations and steps halving to 0.005; four
#: starts, not two, because on a concealed frame-rate error two starts ended at log L -830.6 and
#: four reached -481.1, three of them above -572. Successive halving of the starts after each
#: window: on six development searches it halved the simulations and reached the same optimum in
#: five (the sixth 0.8 nats lower), and it takes a third off the continuation stage of a whole
#: diagnosis ("Successive halving").
CONTINUATION = {
    "n_design": 256,
    "n_keep": 4,
    "cycles0": 3.0,
    "maxfev0": 30,
    "maxfev_step": 25,
    "step0": 0.05,
    "step_ratio": 4.0,
    "step_min": 5e-4,
    "halving": True,
}


def windows(n: int, frames_per_cycle: float, cycles0: float = 3.0) -> list[int]:
    """Window lengths (frames) of the continuation: ``cycles0`` cycles, doubled until ``n``.

    >>> windows(400, 15.0, 3.0)
    [46, 92, 184, 368, 400]
    """
    if n < 2:
        raise ValueError(f"need at least 2 frames, got {n}")
    if not (math.isfinite(frames_per_cycle) and frames_per_cycle > 0):
        return [n]
    w = max(4, int(math.ceil(cycles0 * frames_per_cycle)) + 1)
    out = []
    while w < n:
        out.append(w)
        w *= 2
    return out + [n]


def window_problems(problem: Problem, cycles0: float = 3.0) -> list[Problem]:
    """The problem on the first ``w`` frames of its recording, one per continuation window (the
    last is ``problem`` itself). Each aligns its own prefix over the whole simulated window. A
    prefix that is not a usable recording by itself (no f0 over it: a tremor's quiet stretch, a
    slow onset) is left out, so the search starts at the first window that is one."""
    y = np.asarray(problem.obs_gaw, dtype=float)
    ws = windows(y.size, problem.fps / estimate_f0(y, problem.fps), cycles0)
    out = []
    for w in ws[:-1]:
        try:
            out.append(dataclasses.replace(problem, obs_gaw=y[:w]))
        except ValueError:
            continue
    return out + [problem]


def model_evaluator(problem: Problem, extension: str | None, integrate: bool = True):
    """Batch function ``thetas -> Evaluation`` of the base model (``extension=None``) or of the
    base model plus ``extension`` (:class:`.fit.ExtendedEvaluator`)."""
    if extension is None:
        return ProblemEvaluator(problem)
    from .fit import ExtendedEvaluator

    return ExtendedEvaluator(problem, extension, integrate=integrate)


def model_prior(problem: Problem, extension: str | None, integrate: bool = True):
    """The prior :func:`model_evaluator` samples: the problem's, or the extended one."""
    if extension is None:
        return problem.prior
    from .fit import ExtendedPrior

    return ExtendedPrior(bounds={}, base=problem.prior, extension=extension, integrate=bool(integrate))


def _polish(ev, u: np.ndarray, k: int, last: bool, s: dict, lo, width, state: list) -> tuple[np.ndarray, float]:
    """Nelder-Mead polish of the start ``u`` (unit coordinates) on window ``k``'s evaluator ``ev``;
    returns the new point and the window's optimum (``-inf`` if none was finite). ``state = [n, best_v, best_u]`` is updated in place: simulations made,
    and on the last window the best value seen and its point."""
    from scipy.optimize import minimize

    d = u.size

    def f(z):
        if np.any(z < 0.0) or np.any(z > 1.0):
            return 1e300
        state[0] += 1
        v = float(ev((lo + z * width)[None, :]).loglik[0])
        if last and v > state[1]:
            state[1], state[2] = v, np.array(z, dtype=float)
        return -v if math.isfinite(v) else 1e300

    step = max(s["step0"] / s["step_ratio"] ** k, s["step_min"])
    simplex = np.vstack(
        [u] + [np.clip(u + step * e, 0.0, 1.0) if u[j] + step <= 1.0 else u - step * e for j, e in enumerate(np.eye(d))]
    )
    r = minimize(
        f,
        u,
        method="Nelder-Mead",
        options={
            "maxfev": int(s["maxfev0"] + s["maxfev_step"] * k),
            "initial_simplex": simplex,
            "xatol": 1e-7,
            "fatol": 1e-6,
        },
    )
    if math.isfinite(r.fun) and r.fun < 1e299:
        return np.clip(r.x, 0.0, 1.0), -float(r.fun)
    return u, -math.inf


def _start_state(ev_last, u0: np.ndarray, lo, width) -> tuple[np.ndarray, list]:
    """A start clipped to the unit box and its own whole-window value: the search never returns
    less than its start (a start already fitted to the whole window can drift on the short first
    window)."""
    u = np.clip(u0, 0.0, 1.0)
    v0 = float(ev_last((lo + u * width)[None, :]).loglik[0])
    return u, [1, v0 if math.isfinite(v0) else -math.inf, u.copy()]


class _Continuer:
    """Picklable batch function: each row is a start in unit coordinates; returns an Evaluation
    whose ``loglik`` is the best whole-window log-likelihood reached from it and whose ``extra``
    holds that point (unit coordinates) and the simulations spent."""

    def __init__(self, evaluators, settings: dict):
        self.evaluators = evaluators
        self.s = settings

    def __call__(self, starts) -> Evaluation:
        starts = np.atleast_2d(np.asarray(starts, dtype=float))
        k_all = len(self.evaluators)
        prior = self.s["prior"]
        lo, width = prior.lo, prior.width
        d = lo.size
        out_ll = np.full(len(starts), -np.inf)
        extra = np.full((len(starts), d + 1), np.nan)
        for i, u0 in enumerate(starts):
            u, state = _start_state(self.evaluators[-1], u0, lo, width)
            for k, ev in enumerate(self.evaluators):
                u, _ = _polish(ev, u, k, k == k_all - 1, self.s, lo, width, state)
            out_ll[i] = state[1]
            extra[i, :d] = state[2]
            extra[i, d] = state[0]
        return Evaluation(loglik=out_ll, ok=np.isfinite(out_ll), extra=extra)


class _WindowStep:
    """Picklable batch function of the halving search: one window's polish of each start. A row is
    ``[u (d), n, best_v, best_u (d)]`` (``n = 0``: a new start, whose whole-window value is taken
    first); returns the updated rows in ``extra`` and the window's optimum in ``loglik``."""

    def __init__(self, evaluators, k: int, settings: dict):
        self.evaluators, self.k, self.s = evaluators, k, settings

    def __call__(self, rows) -> Evaluation:
        rows = np.atleast_2d(np.asarray(rows, dtype=float))
        prior = self.s["prior"]
        lo, width = prior.lo, prior.width
        d = lo.size
        last = self.k == len(self.evaluators) - 1
        out = np.empty_like(rows)
        val = np.full(len(rows), -np.inf)
        for i, row in enumerate(rows):
            if row[d] == 0:
                u, state = _start_state(self.evaluators[-1], row[:d], lo, width)
            else:
                u, state = row[:d].copy(), [int(row[d]), float(row[d + 1]), row[d + 2 :].copy()]
            u, val[i] = _polish(self.evaluators[self.k], u, self.k, last, self.s, lo, width, state)
            out[i, :d], out[i, d], out[i, d + 1], out[i, d + 2 :] = u, state[0], state[1], state[2]
        return Evaluation(loglik=val, ok=np.isfinite(val), extra=out)


def _halving_search(evs, chosen: np.ndarray, s: dict, map) -> Evaluation:
    """The starts polished window by window; after each window but the last only the better half
    of them (by that window's optimum, at least one) goes on. Returns, per start, the same
    ``Evaluation`` as :class:`_Continuer` (a dropped start keeps the best it had: ``-inf`` unless
    its whole-window start value was finite) with its simulations."""
    return _halving_searches([evs], [np.asarray(chosen, dtype=float)], [s], map)[0]


class _ManyJobs:
    """Picklable batch function over the starts of several searches at once: a row is ``[job, the
    job's own row (padded with nan to the widest)]``, handed to ``jobs[job]`` by :meth:`_one`, which
    returns the row's log-likelihood and ``[simulations spent, the job's result (padded)]``."""

    row_tasks = True  # each row a long search of its own (importance.BalancedMap)

    def __init__(self, jobs):
        self.jobs = jobs

    def simulations(self, part, result) -> int:
        """Simulations a result cost (the progress tracker's count)."""
        return int(np.nansum(np.asarray(Evaluation.coerce(result).extra)[:, 0]))

    def __call__(self, rows) -> Evaluation:
        rows = np.atleast_2d(np.asarray(rows, dtype=float))
        ll = np.full(len(rows), -np.inf)
        extra = np.full(rows.shape, np.nan)
        for i, row in enumerate(rows):
            job = self.jobs[int(row[0])]
            ll[i], out = self._one(job, job.s["prior"].ndim, row[1:])
            extra[i, : out.size] = out
        return Evaluation(loglik=ll, ok=np.isfinite(ll), extra=extra)


class _ManyWindowStep(_ManyJobs):
    """The joint halving search's window: each row's job is a :class:`_WindowStep`, its row that
    step's ``[u, n, best_v, best_u]``; ``extra`` carries the updated row."""

    @staticmethod
    def _one(step, d, row):
        r = step(row[: 2 * d + 2][None, :])
        return r.loglik[0], np.concatenate([[r.extra[0, d] - row[d]], r.extra[0]])


def _halving_searches(evs_list, chosen_list, settings_list, map) -> list[Evaluation]:
    """:func:`_halving_search` for several searches of one recording at once (their windows are the
    same): at each window the surviving starts of every search go through ``map`` together, one
    start a part, then each search keeps its own better half. A start's path is the one it takes
    alone, so each result equals its own :func:`_halving_search` bit for bit."""
    K = len(evs_list[0])
    if any(len(evs) != K for evs in evs_list):
        raise ValueError("searches run together must share their windows")
    dims = [st["prior"].ndim for st in settings_list]
    rows = [np.hstack([c, np.zeros((len(c), 1)), np.full((len(c), 1), -np.inf), c]) for c in chosen_list]
    alive = [np.arange(len(c)) for c in chosen_list]
    width = 1 + max(2 * d + 2 for d in dims)
    for k in range(K):
        fn = _ManyWindowStep([_WindowStep(evs, k, st) for evs, st in zip(evs_list, settings_list)])
        batch = [
            np.concatenate([[j], r, np.full(width - 1 - r.size, np.nan)])
            for j in range(len(rows))
            for r in rows[j][alive[j]]
        ]
        res = map_evaluate(fn, np.array(batch), map=map, chunk_size=1)
        at = 0
        for j, d in enumerate(dims):
            m = len(alive[j])
            rows[j][alive[j]] = res.extra[at : at + m, 1 : 2 * d + 3]
            val = res.loglik[at : at + m]
            at += m
            if k < K - 1 and m > 1:
                order = np.argsort(-val, kind="stable")
                alive[j] = np.sort(alive[j][order[: max(1, math.ceil(m / 2))]])
    out = []
    for r, d in zip(rows, dims):
        ll = r[:, d + 1]
        out.append(Evaluation(loglik=ll, ok=np.isfinite(ll), extra=np.hstack([r[:, d + 2 :], r[:, d : d + 1]])))
    return out


@dataclass
class SearchResult:
    """Best point of a continuation search (``theta``, in the prior's parameters ``names``), its
    whole-window log-likelihood (integrated over an extension's integrable parameters, as the
    refit's), the simulations made, the windows (frames) and each start's best log-likelihood."""

    names: tuple
    theta: np.ndarray
    loglik: float
    n_simulations: int
    windows: list = field(default_factory=list)
    start_logliks: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return {
            "params": {n: float(v) for n, v in zip(self.names, self.theta)},
            "loglik": float(self.loglik),
            "n_simulations": int(self.n_simulations),
            "windows": list(self.windows),
            "start_logliks": [float(v) for v in self.start_logliks],
        }


class _ManyContinuer(_ManyJobs):
    """The joint search without halving: each row's job is a :class:`_Continuer`, its row a start
    ``u``; ``extra = [n, u (padded)]``: the simulations spent and the best point, in the job's unit
    coordinates."""

    @staticmethod
    def _one(job, d, row):
        r = job(row[:d][None, :])
        return r.loglik[0], np.concatenate([[r.extra[0, d]], r.extra[0, :d]])


def continuation_search(
    problem: Problem,
    extension: str | None = None,
    *,
    starts=(),
    seed: int = 0,
    map=map,
    chunk_size: int = 40,
    integrate: bool = True,
    **settings,
) -> SearchResult:
    """Window-continuation search (module docstring) for the base model (``extension=None``) or
    the base model plus ``extension`` (its integrable parameters integrated out when
    ``integrate``). ``starts``: further start points (rows in the prior's parameters, e.g. a fit's
    best particle), continued besides the design's ``n_keep`` best. ``settings`` override
    :data:`CONTINUATION`. Deterministic for a given ``seed``; the starts run in parallel through
    ``map``."""
    return continuation_searches(
        problem, [(extension, starts, seed)], map=map, chunk_size=chunk_size, integrate=integrate, **settings
    )[0]


def continuation_searches(
    problem: Problem, jobs, *, map=map, chunk_size: int = 40, integrate: bool = True, **settings
) -> list[SearchResult]:
    """:func:`continuation_search` for several models of one recording at once: ``jobs`` is a
    sequence of ``(extension, starts, seed)``. Each job's Sobol design is evaluated in turn, then the
    starts of every job go through ``map`` together, one start a part, so a cluster stays busy while
    the slowest start of one search runs (a search has four to six starts; two workers would
    otherwise wait on each search's last). Each start is continued exactly as alone, so every
    result equals its own :func:`continuation_search` bit for bit. The halving search
    (``halving=True``) goes window by window, every job's surviving starts together, each job
    dropping its own worse half (:func:`_halving_searches`)."""
    from scipy.stats import qmc

    s = {**CONTINUATION, **settings}
    unknown = set(settings) - set(CONTINUATION)
    if unknown:
        raise ValueError(f"unknown continuation settings {sorted(unknown)}; known: {sorted(CONTINUATION)}")
    plans = []
    for extension, starts, seed in jobs:
        prior = model_prior(problem, extension, integrate)
        probs = window_problems(problem, float(s["cycles0"]))
        evs = [model_evaluator(p, extension, integrate) for p in probs]
        d = prior.ndim
        U = (
            qmc.Sobol(d, scramble=True, seed=int(seed)).random(int(s["n_design"]))
            if s["n_design"] > 0
            else np.empty((0, d))
        )
        n_sims = 0
        chosen = []
        if len(U):
            first = map_evaluate(evs[0], prior.lo + U * prior.width, map=map, chunk_size=chunk_size)
            n_sims += len(U)
            order = [j for j in np.argsort(-first.loglik, kind="stable") if math.isfinite(first.loglik[j])]
            chosen += [U[j] for j in order[: int(s["n_keep"])]]
        for th in np.atleast_2d(np.asarray(starts, dtype=float)) if len(starts) else []:
            if th.size != d:
                raise ValueError(f"a start has {th.size} parameters; the prior has {d} ({prior.names})")
            chosen.append(np.clip((th - prior.lo) / prior.width, 0.0, 1.0))
        plans.append({"prior": prior, "probs": probs, "evs": evs, "chosen": chosen, "n": n_sims, "res": None})
    live = [k for k, pl in enumerate(plans) if pl["chosen"]]
    if live and s["halving"]:
        got = _halving_searches(
            [plans[k]["evs"] for k in live],
            [np.array(plans[k]["chosen"]) for k in live],
            [{**s, "prior": plans[k]["prior"]} for k in live],
            map,
        )
        for k, r in zip(live, got):
            plans[k]["res"] = r
    elif live:
        width = 1 + max(plans[k]["prior"].ndim for k in live)
        rows = [
            np.concatenate([[pos], u, np.full(width - 1 - u.size, np.nan)])
            for pos, k in enumerate(live)
            for u in plans[k]["chosen"]
        ]
        fn = _ManyContinuer([_Continuer(plans[k]["evs"], {**s, "prior": plans[k]["prior"]}) for k in live])
        res = map_evaluate(fn, np.array(rows), map=map, chunk_size=1)
        at = 0
        for k in live:
            pl, m, d = plans[k], len(plans[k]["chosen"]), plans[k]["prior"].ndim
            ex = res.extra[at : at + m]
            pl["res"] = Evaluation(
                loglik=res.loglik[at : at + m], ok=res.ok[at : at + m], extra=np.hstack([ex[:, 1 : 1 + d], ex[:, :1]])
            )
            at += m
    out = []
    for pl in plans:
        prior, probs, res = pl["prior"], pl["probs"], pl["res"]
        d = prior.ndim
        if res is None:
            out.append(
                SearchResult(tuple(prior.names), np.full(d, np.nan), -math.inf, pl["n"], [p.n_compare for p in probs])
            )
            continue
        n_sims = pl["n"] + int(np.nansum(res.extra[:, d]))
        j = int(np.argmax(res.loglik))
        theta = prior.lo + res.extra[j, :d] * prior.width
        out.append(
            SearchResult(
                tuple(prior.names),
                theta,
                float(res.loglik[j]),
                n_sims,
                [int(p.obs_gaw.size) for p in probs],
                [float(v) for v in res.loglik],
            )
        )
    return out


def continued_fit(
    problem: Problem,
    found: SearchResult,
    extension: str | None = None,
    *,
    n_particles: int,
    seed: int,
    map=map,
    chunk_size: int = 40,
    integrate: bool = True,
    floor: float = 0.002,
    **smc_options,
):
    """SMC fit of the base model (``extension=None``) or of ``extension``, started from a narrow
    Gaussian reference about ``found.theta`` (sd ``floor`` of each prior width, every sampled
    parameter; :class:`vfcore.inference.reference.GaussianReference`), so it estimates the
    model's log-evidence from the mode the search found (the reference mixes in 10 % of the
    prior, as the rescue's does). Returns ``(log Z, se, posterior)``.

    On a concealed leak that the SMC fits from the prior missed (:ref:`diagnose`): from the search's
    optimum (residual 0.52 mm^2) this fit reached log Z -459.7 +- 0.4 with residual 0.59 mm^2 and
    the leak's area 2.11 mm^2 (truth 2.105) in 384 simulations; the best SMC refit from the prior
    reached -838."""
    from ..inference.smc import smc
    from .fit import fit_extended

    ref = _continued_reference(problem, found, extension, integrate, floor, seed)
    if extension is None:
        post = smc(
            problem, n_particles=n_particles, seed=seed, map=map, chunk_size=chunk_size, reference=ref, **smc_options
        )
    else:
        post = fit_extended(
            problem,
            extension,
            n_particles=n_particles,
            seed=seed,
            map=map,
            chunk_size=chunk_size,
            integrate=integrate,
            reference=ref,
            **smc_options,
        )
    post.info["continuation"] = found.to_dict()
    return float(post.log_evidence), float(post.log_evidence_se), post


def _continued_reference(
    problem: Problem, found: SearchResult, extension: str | None, integrate: bool, floor: float, seed: int
):
    """The narrow Gaussian reference of :func:`continued_fit` about the search's optimum."""
    from ..inference.reference import GaussianReference

    prior = model_prior(problem, extension, integrate)
    if tuple(found.names) != tuple(prior.names):
        raise ValueError(f"the search was over {found.names}, this model's parameters are {prior.names}")
    if not np.all(np.isfinite(found.theta)):
        raise ValueError("the search found no point with a finite log-likelihood")
    return GaussianReference(
        prior, np.asarray(found.theta, dtype=float), np.diag((floor * prior.width) ** 2), eps=0.1, seed=seed
    )


def continued_fits(
    problem: Problem,
    jobs,
    *,
    n_particles: int,
    map=map,
    chunk_size: int = 40,
    integrate: bool = True,
    floor: float = 0.002,
    **smc_options,
) -> list[tuple[float, float, object]]:
    """:func:`continued_fit` of every ``(found, extension, seed)`` of ``jobs`` (entries, not the base model),
    the fits run together (:func:`.together.fit_extended_many`: each as alone, one batch a round), or one
    after another when an SMC option only a whole run takes is given. Returns ``(log Z, se, posterior)``
    per job."""
    from ..inference.smc import WHOLE_RUN_OPTIONS
    from .together import fit_extended_many

    if set(smc_options) & set(WHOLE_RUN_OPTIONS):
        return [
            continued_fit(
                problem,
                f,
                e,
                n_particles=n_particles,
                seed=s,
                map=map,
                chunk_size=chunk_size,
                integrate=integrate,
                floor=floor,
                **smc_options,
            )
            for f, e, s in jobs
        ]
    refs = [_continued_reference(problem, f, e, integrate, floor, s) for f, e, s in jobs]
    posts = fit_extended_many(
        problem,
        [(e, n_particles, s, {"reference": r}) for (_, e, s), r in zip(jobs, refs)],
        map=map,
        chunk_size=chunk_size,
        integrate=integrate,
        **smc_options,
    )
    out = []
    for (f, _, _), post in zip(jobs, posts):
        post.info["continuation"] = f.to_dict()
        out.append((float(post.log_evidence), float(post.log_evidence_se), post))
    return out
