"""A finished SMC run (:class:`.smc.SMCSampler`) as a posterior: its equally weighted particles, evidence,
per-generation history and the warning of a degenerate final ensemble."""

from __future__ import annotations

import math
import warnings

import numpy as np

from .diagnostics import DegenerateEnsembleWarning
from .posterior import Posterior

__all__ = ["posterior_of"]


def posterior_of(sampler, rng: np.random.Generator, *, obs_gaw=None, fps: float | None = None) -> Posterior:
    """The :class:`.posterior.Posterior` of a finished ``sampler``; ``rng`` draws its resampled ensemble.

    Warns (:class:`.diagnostics.DegenerateEnsembleWarning`, attributed to the caller of
    ``SMCSampler.result``) when the last generation's moves left fewer than half the particles distinct or
    accepted under 5 % of the proposals."""
    s = sampler
    msgs = []
    last = s.history[-1] if s.history else {}
    acc = last.get("acceptance", 1.0)
    uniq = last.get("n_unique_after_moves", s.n)
    if uniq < 0.5 * s.n or acc < 0.05:
        msgs.append(
            f"DEGENERATE ENSEMBLE (smc): final generation acceptance {acc:.3f}, {uniq} distinct "
            f"particles of {s.n}; increase max_moves or n_particles."
        )
        warnings.warn(msgs[-1], DegenerateEnsembleWarning, stacklevel=3)
    logw = np.full(s.n, -math.log(s.n))
    post = Posterior.from_weighted(
        s.prior.names,
        s.theta,
        logw,
        rng=rng,
        log_evidence=s.log_evidence,
        log_evidence_se=math.sqrt(s.log_evidence_var),
        n_simulations=s.n_simulations,
        n_failed=s.n_failed,
        method="smc",
        check=False,
        warnings=msgs,
        obs_gaw=obs_gaw,
        fps=fps,
    )
    post.ess = s.last_ess
    post.pareto_k = float("nan")
    if s.ev is not None and s.ev.gaw is not None:
        post.predictive = s.ev
        post.predictive_index = np.arange(s.n)
    if s.ev is not None and len(s.ev.loglik):
        post.info["max_loglik"] = float(np.max(s.ev.loglik))
    post.info.update(
        {
            "generations": s.history,
            "n_generations": s.generation,
            "n_particles": s.n,
            "seed": s.seed,
            "temperatures": [h["phi"] for h in s.history],
            "reference": s.reference is not None,
        }
    )
    if s.delayed:
        post.info.update(
            {"delayed_acceptance": True, "n_screened": s.n_screened, "n_screen_rejected": s.n_screen_rejected}
        )
    return post
