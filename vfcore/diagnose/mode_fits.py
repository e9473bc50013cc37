"""Fits started in a known material mode: the base model (or an entry) on a box around a fit's material
posterior (:func:`base_near`, a lower bound on its evidence), and an entry fitted by an SMC started from a
fit's material particles (:func:`reference_refit`, :func:`shared_mode_refit`, an evidence estimate).
The rescue, the mode checks, the nested check and the shared mode are made of these."""

from __future__ import annotations

import math

import numpy as np

from ..inference.posterior import Posterior
from ..inference.problem import Problem
from .fit import fit_extended
from .seeds import spawn_seed

__all__ = ["base_near", "reference_refit", "reference_refits", "shared_mode_refit"]


def base_near(
    problem: Problem,
    post: Posterior,
    *,
    n_particles: int,
    seed: int,
    map=map,
    chunk_size: int = 40,
    half_width: float = 0.025,
    n_sd: float = 4.0,
    extension: str | None = None,
    integrate: bool = True,
    max_shifts: int = 3,
    **smc_options,
):
    """The base model re-fitted around the material mode of an extended fit ``post``.

    SMC of the base model on the box ``mean +- max(n_sd * sd, half_width * prior width)`` of
    ``post``'s material parameters (clipped to the prior). With ``Z_box`` its evidence under the
    uniform prior on the box and ``V_box / V`` the box's prior probability,
    ``log Z_base >= log Z_box + log(V_box / V)`` because the likelihood is >= 0 outside the box:
    a lower bound on the base evidence *in the mode the extended fit found*. Returns
    ``(log Z bound, se, posterior)``. At the defaults a box over d material parameters costs at most
    d log(0.05) of prior volume (-9 nats for three, -15 for five), small against the gains it is compared with.
    ``extension``: refit that extended model instead of the base model (its own parameters keep
    their whole prior), for the nested check of :func:`diagnose`; the bound is then on its evidence.

    A box that cuts the mode off is not a refit of that mode: a posterior piled against an edge
    that the box, not the prior, put there is a truncated posterior whose fit quality is set by
    where the edge happened to fall (and a verdict taken from it flips with the last bits of the
    arithmetic). Such a box is re-centred on the truncated posterior (same widths) and the fit
    repeated, at most ``max_shifts`` times (:func:`_box_edge_hits`); every box tried is recorded in
    ``info["boxes"]`` and the last one in ``info["box"]``. The bound holds for every box.
    """
    import dataclasses as dc

    from ..inference.prior import Prior
    from ..inference.smc import smc

    prior = problem.prior
    nb = prior.ndim
    mean, sd = np.asarray(post.mean[:nb], float), np.asarray(post.sd[:nb], float)
    half = [
        max(n_sd * float(sd[i]), half_width * (prior.bounds[n][1] - prior.bounds[n][0]))
        for i, n in enumerate(prior.names)
    ]
    boxes = []
    for attempt in range(max(0, int(max_shifts)) + 1):
        box, log_vol = {}, 0.0
        for i, name in enumerate(prior.names):
            lo, hi = prior.bounds[name]
            a, b = max(lo, float(mean[i]) - half[i]), min(hi, float(mean[i]) + half[i])
            if not b > a:
                a, b = lo, hi
            box[name] = (a, b)
            log_vol += math.log((b - a) / (hi - lo))
        pb = dc.replace(problem, prior=Prior(bounds=box, fixed=dict(prior.fixed)))
        if extension is None:
            near = smc(
                pb,
                n_particles=n_particles,
                seed=spawn_seed(seed, attempt),
                map=map,
                chunk_size=chunk_size,
                **smc_options,
            )
        else:
            near = fit_extended(
                pb,
                extension,
                n_particles=n_particles,
                seed=spawn_seed(seed, attempt),
                map=map,
                chunk_size=chunk_size,
                integrate=integrate,
                **smc_options,
            )
        boxes.append(box)
        hits = _box_edge_hits(near, box, prior)
        if not hits:
            break
        mean = np.asarray(near.mean[:nb], float)
    near.info["box"] = box
    near.info["boxes"] = boxes
    near.info["box_edge_hits"] = hits
    near.info["log_box_probability"] = log_vol
    return float(near.log_evidence) + log_vol, float(near.log_evidence_se), near


def _box_edge_hits(post: Posterior, box: dict, prior, *, edge_fraction: float = 0.05) -> list[str]:
    """Material parameters whose posterior ``post`` piles against an edge of ``box`` that lies
    inside the prior: the posterior mean within ``edge_fraction`` of the box width of that edge.
    A posterior of a smooth likelihood on a box that contains its mode sits well inside the box
    (the box's half-width is at least 4 posterior sds); one within 5 % of the width of an edge is
    the edge's, not the data's."""
    hits = []
    for i, name in enumerate(prior.names):
        a, b = box[name]
        lo, hi = prior.bounds[name]
        m, tol = float(post.mean[i]), edge_fraction * (b - a)
        if (a > lo and m - a < tol) or (b < hi and b - m < tol):
            hits.append(name)
    return hits


def reference_refit(
    problem: Problem,
    post: Posterior,
    extension: str,
    *,
    n_particles: int,
    seed: int,
    map=map,
    chunk_size: int = 40,
    inflate: float = 2.0,
    integrate: bool = True,
    **smc_options,
):
    """The extended model ``extension`` fitted by an SMC started from ``post`` (a fit of the base
    model) instead of the prior: :func:`vfcore.inference.reference.reference_from_posterior` on the
    extended prior (the base's material particles give the Gaussian, inflated ``inflate`` times;
    the extension's sampled parameters are uniform over their prior). The result's log-evidence
    estimates the extended model's evidence (generalized stepping-stone path), not a bound.
    Returns ``(log Z, se, posterior)``."""
    ref = base_reference(problem, post, extension, inflate, integrate, seed)
    near = fit_extended(
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
    return referenced(near, ref, inflate)


def base_reference(problem: Problem, post: Posterior, extension: str, inflate: float, integrate: bool, seed: int):
    """The Gaussian reference of :func:`reference_refit`: ``post``'s material particles, inflated, on the
    extended prior."""
    from ..inference.reference import reference_from_posterior
    from .fit import ExtendedPrior

    prior = ExtendedPrior(bounds={}, base=problem.prior, extension=extension, integrate=bool(integrate))
    return reference_from_posterior(prior, post, inflate=inflate, seed=seed)


def referenced(near: Posterior, ref, inflate: float) -> tuple[float, float, Posterior]:
    """``(log Z, se, posterior)`` of a reference-started fit, its reference recorded in its ``info``."""
    near.info["reference"] = {"inflate": inflate, "p_inside": ref.p_inside}
    return float(near.log_evidence), float(near.log_evidence_se), near


def reference_refits(
    problem: Problem,
    post: Posterior,
    jobs,
    *,
    map=map,
    chunk_size: int = 40,
    inflate: float = 2.0,
    integrate: bool = True,
    **smc_options,
) -> list[tuple[float, float, Posterior]]:
    """:func:`reference_refit` of each ``(extension, n_particles, seed)`` of ``jobs``, all run together
    (:func:`.together.fit_extended_many`: each fit as alone, one batch a round), or one after another when
    an SMC option only a whole run takes is given. Returns ``(log Z, se, posterior)`` per job."""
    from ..inference.smc import WHOLE_RUN_OPTIONS
    from .together import fit_extended_many

    if set(smc_options) & set(WHOLE_RUN_OPTIONS):
        return [
            reference_refit(
                problem,
                post,
                e,
                n_particles=n,
                seed=s,
                map=map,
                chunk_size=chunk_size,
                inflate=inflate,
                integrate=integrate,
                **smc_options,
            )
            for e, n, s in jobs
        ]
    refs = [base_reference(problem, post, e, inflate, integrate, s) for e, _, s in jobs]
    posts = fit_extended_many(
        problem,
        [(e, n, s, {"reference": r}) for (e, n, s), r in zip(jobs, refs)],
        map=map,
        chunk_size=chunk_size,
        integrate=integrate,
        **smc_options,
    )
    return [referenced(near, ref, inflate) for near, ref in zip(posts, refs)]


def _material_view(post: Posterior, n_base: int):
    """The material part (the first ``n_base`` parameters) of an extended fit, as the Gaussian
    reference needs it: names, weighted mean and covariance."""
    from types import SimpleNamespace

    return SimpleNamespace(
        names=tuple(post.names[:n_base]),
        mean=np.asarray(post.mean, dtype=float)[:n_base],
        cov=np.asarray(post.cov, dtype=float)[:n_base, :n_base],
    )


def shared_mode_refit(
    problem: Problem,
    lead: Posterior,
    extension: str,
    *,
    n_particles: int,
    seed: int,
    map=map,
    chunk_size: int = 40,
    inflate: float = 2.0,
    integrate: bool = True,
    **smc_options,
):
    """``extension`` fitted by an SMC started from the material mode of another entry's fit
    ``lead`` (:func:`reference_refit` on ``lead``'s material parameters; ``extension``'s own
    sampled parameters uniform over their prior). Returns ``(log Z, se, posterior)``; the
    log-evidence estimates ``extension``'s evidence, as any refit's does."""
    return reference_refit(
        problem,
        _material_view(lead, problem.prior.ndim),
        extension,
        n_particles=n_particles,
        seed=seed,
        map=map,
        chunk_size=chunk_size,
        inflate=inflate,
        integrate=integrate,
        **smc_options,
    )
