"""Fit extended models: the base forward model plus one catalogued extension.

An extended fit estimates the base model's parameters (those of the base ``Problem``'s prior)
together with the extension's parameters — sampled jointly, or, for the waveform-level ones,
integrated out of each simulation's likelihood by quadrature (``integrate=True``, the default of
:func:`fit_extended`; :mod:`.quadrature`) — with the same likelihood (Eq. 15, sigma_e, the same
compared frames and the same alignment) as the base fit, so the log-evidences of base and
extended fits are comparable (:ref:`validation-diagnose-pipeline-refits-started-from-the-base`).

Extensions act in one of two ways (``Extension.kind``):

- **observation** (leak, scale, exposure, frame_rate, zipper, asymmetry): the simulation is the
  base model's; the extension maps its glottal area, at 10x the camera rate
  (:attr:`vfcore.result.SimResult.gaw_hr`), to what the camera records, before alignment.
  These operators are defined on the oversampled waveform (:mod:`.observers`), so that they stay
  continuous in their parameters (a frame-rate grid would quantise time shifts).
- **forward** (sep_ratio, epithelium, subglottal): a ``SimConfig`` field of the forward model,
  so each draw re-simulates. ``lr_stiffness`` (two folds of different stiffness) simulates a
  second, right fold with its moduli scaled and combines the two (:func:`entrain_pair`), so each
  draw costs two simulations.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..inference.prior import Prior
from ..inference.problem import Evaluation, Problem, score_results
from ..result import HR_OVERSAMPLE
from .extensions import SUB_LOG10_Z_OFF, Extension, get
from .observers import entrain_pair, observe_extended, observer, pair_observer, right_fold_params

__all__ = [
    "ExtendedPrior",
    "ExtendedEvaluator",
    "observe_extended",
    "observer",
    "extended_config",
    "fit_extended",
    "entrain_pair",
    "pair_observer",
    "right_fold_params",
    "integrated_summary",
    "param_table",
    "finish_extended",
    "simulate_rows",
]


# ------------------------------------------------------------------------------------ prior
@dataclass(frozen=True, eq=False)
class ExtendedPrior(Prior):
    """Uniform prior over the base prior's parameters followed by an extension's parameters.

    ``names`` lists the base names (in ``PARAM_NAMES`` order) then the extension's.
    ``split(theta)`` returns (base theta, {extension name: value}).
    """

    base: Prior | None = None
    extension: str = ""
    #: leave out the extension's integrable parameters (integrated per simulation by quadrature)
    integrate: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.base, Prior):
            raise ValueError("ExtendedPrior needs a base Prior")
        ext = get(self.extension)
        b = dict(self.base.bounds)
        skip = set(ext.integrable) if self.integrate else set()
        for p in ext.params:
            if p.name in skip:
                continue
            if p.name in b:
                raise ValueError(f"extension parameter {p.name!r} clashes with a base parameter")
            b[p.name] = (float(p.lo), float(p.hi))
        object.__setattr__(self, "bounds", b)
        object.__setattr__(self, "fixed", dict(self.base.fixed))

    @property
    def n_base(self) -> int:
        return self.base.ndim

    def split(self, theta) -> tuple[np.ndarray, dict[str, float]]:
        theta = np.asarray(theta, dtype=float)
        nb = self.n_base
        return theta[:nb], dict(zip(self.names[nb:], map(float, theta[nb:])))

    def to_params(self, theta):
        return self.base.to_params(self.split(theta)[0])

    def to_dict(self) -> dict:
        return {"base": self.base.to_dict(), "extension": self.extension, "integrate": self.integrate}

    def __repr__(self) -> str:
        return f"ExtendedPrior({self.base!r} + {self.extension}{' (integrated)' if self.integrate else ''})"


def extended_config(config, name: str, phi: dict):
    """The ``SimConfig`` of a forward-level extension ``name`` with parameters ``phi``."""
    if name == "sep_ratio":
        return dataclasses.replace(config, sep_ratio=phi["sep_ratio"])
    if name == "epithelium":
        h = phi.get("h_epith_mm", 0.05)
        if h <= 0.0:  # no membrane: the base model
            return config
        return dataclasses.replace(config, epithelium_E_kpa=phi["E_epith_kpa"], epithelium_h_mm=h)
    if name == "subglottal":
        if phi["log10_Z_sub"] <= SUB_LOG10_Z_OFF:  # no coupling: the base model
            return config
        return dataclasses.replace(
            config, subglottal_modes=((phi["f_sub_hz"], phi.get("zeta_sub", 0.1), 10.0 ** phi["log10_Z_sub"]),)
        )
    raise ValueError(f"{name!r} is not a forward-level extension")


# -------------------------------------------------------------------------------- evaluator
#: coarse quadrature cells per integrated dimension (:func:`.quadrature.integrate_loglik`); the
#: frame-rate ratio is pinned by the drift of ~20 compared cycles, a peak ~1e-3 wide in a 0.2 prior;
#: the leak area (a peak ~0.05 mm^2 wide in 3 mm^2) as finely as a 1-D entry, its chink fraction coarser
QUAD_CELLS = {"frame_rate": 64, "leak": (24, 6)}
QUAD_CELLS_1D = 24
QUAD_CELLS_2D = 6


def quad_cells(name: str, d: int):
    """Coarse cells per integrated dimension of entry ``name`` with ``d`` integrated parameters:
    an int (every dimension) or one per dimension."""
    return QUAD_CELLS.get(name, QUAD_CELLS_1D if d == 1 else QUAD_CELLS_2D)


def simulate_rows(rows: list, configs: list) -> list:
    """``simulate_many`` of the rows, each with its configuration, in lock-step blocks; where the
    batch raises (a configuration the kernel refuses), row by row, so each failing row is reported
    as its own exception and the others still run."""
    from ..batch import LOCKSTEP_WIDTH, simulate_many

    if not rows:
        return []
    try:
        return simulate_many(rows, block=LOCKSTEP_WIDTH, configs=configs)
    except Exception:  # noqa: BLE001 - find the failing row(s) one by one
        from ..forward import simulate

        out: list = []
        for p, c in zip(rows, configs):
            try:
                out.append(simulate(p, c))
            except Exception as exc:  # noqa: BLE001 - reported per row
                out.append(exc)
        return out


class ExtendedEvaluator:
    """Picklable batch function ``thetas (k, d) -> Evaluation`` for an extended model; the
    likelihood, compared frames and alignment are the base ``problem``'s.

    ``integrate=False``: ``thetas`` hold the base parameters and all the extension's (joint).
    ``integrate=True``: the extension's integrable parameters (``Extension.integrable``: those
    that act on the simulated waveform only) are integrated out of each simulation's likelihood
    by quadrature over their uniform prior (:mod:`.quadrature`), so ``thetas`` hold the base
    parameters and the remaining extension parameters (``self.prior``), and each draw's
    log-likelihood is the log marginal likelihood. Its prediction is read at the quadrature's
    best point; ``Evaluation.extra`` holds, per draw, the conditional posterior mean and sd of
    each integrated parameter (``mean_1, sd_1, mean_2, ...``, in ``self.integrated`` order), then
    per parameter its *null drop*: the log-likelihood at the quadrature's best point minus that
    at the same point with this parameter set to its null value (``ExtParam.null``; nan when it
    has none). :func:`.rank.null_consistent` uses it to reject nulls that lie between modes.
    """

    def __init__(self, problem: Problem, extension: str, integrate: bool = False):
        self.problem = problem
        self.name = extension
        if not get(extension).implemented:
            raise NotImplementedError(f"extension {extension!r} is not implemented")
        self.integrated = tuple(get(extension).integrable) if integrate else ()
        self.prior = ExtendedPrior(bounds={}, base=problem.prior, extension=extension, integrate=bool(integrate))

    @property
    def extension(self) -> Extension:
        return get(self.name)  # looked up, not stored: catalogue entries hold closures

    def _plan(self, base_params, phis, pairs: bool = False) -> tuple[list, list, list]:
        """What the draws need simulated: ``(rows, configs, slots)``, the simulations' parameters and
        configurations, and per draw the exception that stopped it (a configuration that cannot be
        built) or the indices of the rows its result reads (two for ``lr_stiffness``: left, right).
        Every configuration differs from the problem's only in ``vfcore.batch.PER_SAMPLE_FIELDS``,
        so the rows of every entry can share lock-step blocks (:class:`ExtendedPool`)."""
        ext = self.extension
        cfg = self.problem.config
        n = len(base_params)
        if ext.kind == "observation":
            return list(base_params), [cfg] * n, [(i,) for i in range(n)]
        if ext.name == "lr_stiffness":
            rights = [right_fold_params(p, phi["log2_lr_Q"]) for p, phi in zip(base_params, phis)]
            return list(base_params) + rights, [cfg] * (2 * n), [(i, n + i) for i in range(n)]
        # forward-level: each draw has its own configuration; the lock-step kernel takes the
        # extensions per row, so the draws still run in blocks
        rows, cfgs, slots = [], [], []
        for p, phi in zip(base_params, phis):
            try:
                c = extended_config(cfg, ext.name, phi)
            except Exception as exc:  # noqa: BLE001 - reported per draw
                slots.append(exc)
                continue
            slots.append((len(rows),))
            rows.append(p)
            cfgs.append(c)
        return rows, cfgs, slots

    def _assemble(self, sims: list, slots: list, phis, pairs: bool = False) -> list:
        """Per draw, what :meth:`_score` reads: a ``SimResult`` or an exception; for ``lr_stiffness``
        the left fold's result with its area replaced by :func:`entrain_pair` (flow and contact stay
        the left fold's), or with ``pairs=True`` the pair ``(left, right)`` (the lag is then
        integrated by :meth:`_integrated`)."""
        if self.name != "lr_stiffness":
            return [s if isinstance(s, BaseException) else sims[s[0]] for s in slots]
        fps = self.problem.config.fps
        out: list = []
        for (i, j), phi in zip(slots, phis):
            left, right = sims[i], sims[j]
            if isinstance(left, BaseException) or not left.ok:
                out.append(left)
                continue
            if isinstance(right, BaseException) or not right.ok:
                msg = right if isinstance(right, BaseException) else right.message
                out.append(RuntimeError(f"right fold: {msg}"))
                continue
            if pairs:
                out.append((left, right))
                continue
            try:
                hr = entrain_pair(left.gaw_hr, right.gaw_hr, fps, phi["lr_lag"])
                out.append(dataclasses.replace(left, gaw_hr=hr, gaw=hr[::HR_OVERSAMPLE].copy()))
            except Exception as exc:  # noqa: BLE001 - reported per draw
                out.append(exc)
        return out

    def _simulate(self, base_params, phis, pairs: bool = False) -> list:
        rows, cfgs, slots = self._plan(base_params, phis, pairs)
        return self._assemble(simulate_rows(rows, cfgs), slots, phis, pairs)

    def _score(self, results: list, splits: list) -> Evaluation:
        phis = [phi for _, phi in splits]
        if self.integrated:
            return self._integrated(results, phis)
        pb = self.problem
        observe = None
        if self.extension.kind == "observation":

            def observe(i, hr):
                return observe_extended(self.name, hr, pb.fps, splits[i][1], pb.config.length_mm)

        return score_results(results, pb, observe)

    def _draws(self, thetas) -> tuple[list, list, list]:
        """``(splits, base parameters, extension parameters)`` of the draws ``thetas`` (k, d)."""
        splits = [self.prior.split(th) for th in np.atleast_2d(np.asarray(thetas, dtype=float))]
        return splits, [self.problem.prior.to_params(b) for b, _ in splits], [phi for _, phi in splits]

    def __call__(self, thetas) -> Evaluation:
        splits, base_params, phis = self._draws(thetas)
        pairs = bool(self.integrated)
        return self._score(self._simulate(base_params, phis, pairs=pairs), splits)

    def _integrated(self, results, phis) -> Evaluation:
        """Score each simulation with the integrated parameters integrated out (class docstring)."""
        from ..inference.scoring import aligned_loglik, aligned_logliks, contact_means, cycle_means
        from . import quadrature as _q

        pb = self.problem
        ext = self.extension
        names = self.integrated
        lo = np.array([ext.bounds()[n][0] for n in names])
        hi = np.array([ext.bounds()[n][1] for n in names])
        cells = quad_cells(self.name, len(names))
        max_lag, n_cmp = pb.window
        k = len(results)
        loglik = np.full(k, -np.inf)
        ok = np.zeros(k, dtype=bool)
        gaw = np.full((k, n_cmp), np.nan, dtype=np.float32)
        flow, cmean, cmax, cimp, cin = (np.full(k, np.nan) for _ in range(5))
        extra = np.full((k, 3 * len(names)), np.nan)
        null_of = {e.name: e.null for e in ext.params}
        nulls = [null_of[n] for n in names]
        messages = []
        for i, r in enumerate(results):
            try:
                if isinstance(r, BaseException):
                    raise r
                if isinstance(r, tuple):
                    left, right = r
                    see = pair_observer(left.gaw_hr, right.gaw_hr, pb.fps)
                    fwd = dict(phis[i])

                    def obs_fn(phi, see=see):
                        return see(phi["lr_lag"])

                    r = left
                else:
                    if not r.ok:
                        raise RuntimeError(r.message or "simulation failed")
                    obs_fn = observer(self.name, np.asarray(r.gaw_hr, dtype=float), pb.fps, pb.config.length_mm)
                    fwd = dict(phis[i])  # an observation entry's sampled parameters, if any

                def look(point, obs_fn=obs_fn, fwd=fwd):
                    hr = obs_fn({**fwd, **dict(zip(names, map(float, point)))})
                    if hr[::HR_OVERSAMPLE].size < max_lag + n_cmp or not np.all(np.isfinite(hr)):
                        raise RuntimeError("observed GAW too short or not finite")
                    return hr

                def score(point, look=look):
                    return aligned_loglik(look(point), pb)

                def fn(points, look=look):
                    # every point's waveform aligned in one batch (the same bytes as one by one)
                    out = np.full(len(points), -np.inf)
                    seen, at = [], []
                    for j, pt in enumerate(points):
                        try:
                            seen.append(look(pt))
                            at.append(j)
                        except (RuntimeError, ValueError):
                            pass
                    if seen:
                        try:
                            out[at] = aligned_logliks(np.stack(seen), pb)[0]
                        except (RuntimeError, ValueError):
                            pass
                    return out

                q = _q.integrate_loglik(fn, lo, hi, n0=cells)
                if not math.isfinite(q.log_mean):
                    raise RuntimeError("no integrated parameter value gives a finite likelihood")
                gaw[i] = score(q.best)[1]
                drops = np.full(len(names), np.nan)
                for j, nv in enumerate(nulls):
                    if nv is not None and lo[j] <= nv <= hi[j]:
                        at_null = np.array(q.best, dtype=float)
                        at_null[j] = nv
                        drops[j] = q.best_ll - fn(at_null[None, :])[0]
            except Exception as exc:  # noqa: BLE001 - one bad draw must not sink an ensemble
                messages.append(f"{i}: {type(exc).__name__}: {exc}")
                continue
            loglik[i] = q.log_mean + pb.measurement_loglik(r.params)  # constant in the integrated parameters
            ok[i] = True
            extra[i, 0 : 2 * len(names) : 2] = q.mean
            extra[i, 1 : 2 * len(names) : 2] = q.sd
            extra[i, 2 * len(names) :] = drops
            flow[i], cmean[i], cmax[i] = cycle_means(r)
            cimp[i], cin[i] = contact_means(r)
        return Evaluation(
            loglik=loglik,
            ok=ok,
            gaw=gaw,
            mean_flow=flow,
            mean_contact=cmean,
            max_contact=cmax,
            extra=extra,
            messages=tuple(messages),
            contact_impulse=cimp,
            contact_pressure_in_contact=cin,
        )


def integrated_summary(post, names) -> dict[str, dict[str, float]]:
    """Posterior mean and sd of integrated parameters from the final particles' conditional
    means and sds (``Evaluation.extra``): a mixture over the resampled particles,
    ``var = mean(sd_i^2 + m_i^2) - mean(m_i)^2``; ``null_drop``: the median over the particles of
    the log-likelihood drop at the parameter's null value (nan: no null)."""
    rp = post.resampled_predictive()
    if rp is None or rp.extra is None:
        raise ValueError("the posterior carries no integrated-parameter summaries")
    ok = np.asarray(rp.ok, dtype=bool)
    ex = np.asarray(rp.extra, dtype=float)[ok]
    out = {}
    for j, n in enumerate(names):
        m, s = ex[:, 2 * j], ex[:, 2 * j + 1]
        mu = float(np.mean(m))
        out[n] = {"mean": mu, "sd": float(math.sqrt(max(float(np.mean(s * s + m * m)) - mu * mu, 0.0)))}
        if ex.shape[1] >= 3 * len(names):
            d = ex[:, 2 * len(names) + j]
            d = d[np.isfinite(d)]
            out[n]["null_drop"] = float(np.median(d)) if d.size else math.nan
    return out


def param_table(post) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """Names, means and sds of every parameter of a fit: the sampled ones, then the integrated
    ones (``post.info["integrated"]``, set by :func:`fit_extended`)."""
    integ = post.info.get("integrated") or {}
    names = tuple(post.names) + tuple(integ)
    mean = np.concatenate([np.asarray(post.mean, float), [v["mean"] for v in integ.values()]])
    sd = np.concatenate([np.asarray(post.sd, float), [v["sd"] for v in integ.values()]])
    return names, mean, sd


def null_drops(post) -> dict[str, float]:
    """Median log-likelihood drop at the null value of each integrated parameter of a fit
    (:func:`integrated_summary`'s ``null_drop``; empty for a fit with none)."""
    integ = post.info.get("integrated") or {}
    return {n: v["null_drop"] for n, v in integ.items() if math.isfinite(v.get("null_drop", math.nan))}


def fit_extended(
    problem: Problem,
    extension: str,
    *,
    n_particles: int = 80,
    seed: int = 0,
    map=map,
    chunk_size: int = 40,
    integrate: bool = True,
    **smc_options,
):
    """Tempered-SMC fit of the base model + ``extension``.

    ``integrate=True`` (default): the extension's waveform-level parameters are integrated out of
    each simulation's likelihood by quadrature and the SMC samples the rest
    (:class:`ExtendedEvaluator`); their posterior summaries are in ``post.info["integrated"]``
    (:func:`param_table` lists all parameters). ``integrate=False``: SMC joint in all parameters.
    Returns a :class:`vfcore.inference.Posterior` whose ``log_evidence`` is comparable to the
    base fit's (the same integral either way).
    """
    from ..inference.smc import smc

    ev = ExtendedEvaluator(problem, extension, integrate=integrate)
    post = smc(ev, prior=ev.prior, n_particles=n_particles, seed=seed, map=map, chunk_size=chunk_size, **smc_options)
    return finish_extended(post, problem, ev)


def finish_extended(post, problem: Problem, ev: ExtendedEvaluator):
    """An extended fit's posterior with the problem's observation and what the evaluator integrated out."""
    post.obs_gaw = problem.obs_compared
    post.fps = problem.fps
    post.area_scale = problem.area_scale
    post.info["extension"] = ev.name
    if ev.integrated:
        post.info["integrated"] = integrated_summary(post, ev.integrated)
    return post
