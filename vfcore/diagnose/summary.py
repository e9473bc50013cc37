"""What a fit says about the recording: its predicted waveforms, its residual and measures, its best
particles. Every stage of the diagnosis summarises its fits with :func:`fit_summary`, and the report
carries those summaries."""

from __future__ import annotations

import numpy as np

from ..inference.posterior import Posterior
from .fit import null_drops, param_table
from .locate import locate, measure_pvalues, noise_sd

__all__ = ["predicted_gaws", "fit_summary", "best_particles"]


def predicted_gaws(post: Posterior) -> np.ndarray:
    """The predicted GAWs of ``post``'s resampled particles whose simulation succeeded, as recorded (times
    the area scale where it is unknown: :meth:`~vfcore.inference.posterior.Posterior.recorded_gaws`), shape
    ``(n_ok, n_frames)``, mm^2."""
    return post.recorded_gaws()


def fit_summary(post: Posterior, obs: np.ndarray, fps: float, sigma_e: float | None = None) -> dict:
    """Residual RMS, phase location, measure p-values and parameter summary of one fit.

    The p-values' replicated recordings carry the recording's own noise sd, estimated from it
    (:func:`.locate.noise_sd`; ``predictive_noise_sd``), unless ``sigma_e`` is given: the
    likelihood's nominal sigma_e is a scale of the fit, not the camera's noise, and a wrong
    noise level decides the noise-sensitive measures (:ref:`diagnose`)."""
    g = predicted_gaws(post)
    y = np.asarray(obs, dtype=float)[: g.shape[1]]
    loc = locate(y, g, fps)
    s_pp = noise_sd(y, g) if sigma_e is None else float(sigma_e)
    pv = measure_pvalues(g, y, fps, sigma_e=s_pp)
    drops = null_drops(post)
    return {
        "residual_rms": float(np.sqrt(np.mean((y - g.mean(axis=0)) ** 2))),
        "phase_rms": loc.phase_rms,
        "dominant_phase": loc.dominant_phase,
        "concentration": loc.concentration(),
        "pvalues": {k: v.p_two_sided for k, v in pv.items()},
        "measures": {
            k: {"observed": v.observed, "predicted": v.pred_mean, "predicted_sd": v.pred_sd} for k, v in pv.items()
        },
        "predictive_noise_sd": s_pp,
        "params": {
            n: {"mean": float(m), "sd": float(s), **({"null_drop": drops[n]} if n in drops else {})}
            for n, m, s in zip(*param_table(post))
        },
        "log_evidence": float(post.log_evidence),
        "log_evidence_se": float(post.log_evidence_se),
        "n_simulations": int(post.n_simulations),
    }


def best_particles(post: Posterior, m: int) -> np.ndarray:
    """Up to ``m`` distinct particles of the base posterior, heaviest first."""
    w = np.exp(post.log_weights)
    order = np.argsort(-w, kind="stable")
    out, seen = [], set()
    for i in order:
        key = tuple(np.round(post.samples[i], 12))
        if key in seen or w[i] <= 0:
            continue
        seen.add(key)
        out.append(post.samples[i])
        if len(out) == m:
            break
    return np.array(out)
