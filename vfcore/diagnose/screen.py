"""Screening: which catalogue entries are worth a full refit (:ref:`diagnose-pipeline-screen`).

Every implemented extension is tried at a few base-posterior particles: an observation-level one at
``screen_obs`` parameter draws each (no new simulation: the operators act on the stored oversampled
waveform), a forward-level one at ``screen_fwd`` scrambled-Sobol draws of its parameters,
re-simulated. The score is the best log-likelihood reached minus the best base log-likelihood at the
same particles: an optimistic bound on what the extension can gain at the base's material
parameters. It only decides which entries are refitted; it never names one.
"""

from __future__ import annotations

import time

import numpy as np

from ..inference.posterior import Posterior
from ..inference.problem import Problem, aligned_loglik
from .extensions import get
from .fit import ExtendedEvaluator, observe_extended
from .seeds import spawn_seed, stage_seed
from .state import DiagnosisState, Run
from .summary import best_particles

__all__ = ["screen", "screen_catalogue"]


def _sobol(d: int, n: int, seed: int) -> np.ndarray:
    import warnings

    from scipy.stats import qmc

    with warnings.catch_warnings():  # balance is best at powers of 2; any n is still a valid design
        warnings.simplefilter("ignore", UserWarning)
        return qmc.Sobol(d, scramble=True, seed=seed).random(n)


def screen(
    problem: Problem,
    base: Posterior,
    candidates,
    *,
    n_theta: int = 6,
    screen_obs: int = 200,
    screen_fwd: int = 8,
    n_theta_fwd: int = 2,
    seed: int = 0,
    map=map,
) -> dict[str, dict]:
    """Screening scores (see module docstring), name -> {"score", "best_phi", "n_simulations"}."""
    from ..batch import simulate_many

    thetas = best_particles(base, n_theta)
    params = [problem.prior.to_params(t) for t in thetas]
    res = simulate_many(params, problem.config, block=max(1, len(params)))

    def ll_of(hr):
        return aligned_loglik(hr, problem)[0]

    base_ll = np.array([ll_of(np.asarray(r.gaw_hr, float)) if r.ok else -np.inf for r in res])
    best_base = float(np.max(base_ll))
    out: dict[str, dict] = {}
    for k, name in enumerate(candidates):
        ext = get(name)
        lo = np.array([p.lo for p in ext.params])
        hi = np.array([p.hi for p in ext.params])
        if ext.kind == "observation":
            u = _sobol(len(lo), screen_obs, spawn_seed(seed, k))
            phis = lo + u * (hi - lo)
            best, best_phi = -np.inf, None
            for r in res:
                if not r.ok:
                    continue
                hr0 = np.asarray(r.gaw_hr, float)
                for ph in phis:
                    phi = dict(zip(ext.param_names, ph))
                    try:
                        ll = ll_of(observe_extended(name, hr0, problem.fps, phi, problem.config.length_mm))
                    except Exception:  # noqa: BLE001 - a draw that cannot be observed scores -inf
                        continue
                    if ll > best:
                        best, best_phi = ll, phi
            out[name] = {"score": best - best_base, "best_phi": best_phi, "n_simulations": 0}
        else:
            ev = ExtendedEvaluator(problem, name, integrate=False)
            u = _sobol(len(lo), screen_fwd, spawn_seed(seed, k))
            phis = lo + u * (hi - lo)
            rows = np.array([np.concatenate([t, ph]) for t in thetas[:n_theta_fwd] for ph in phis])
            parts = list(map(ev, np.array_split(rows, max(1, min(len(rows), 2)))))
            lls = np.concatenate([p.loglik for p in parts])
            j = int(np.argmax(lls))
            out[name] = {
                "score": float(lls[j] - best_base),
                "best_phi": dict(zip(ext.param_names, rows[j, len(thetas[0]) :])) if np.isfinite(lls[j]) else None,
                "n_simulations": int(rows.shape[0]),
            }
    out["_base"] = {"best_base_loglik": best_base, "n_simulations": len(params)}
    return out


def screen_catalogue(run: Run, st: DiagnosisState) -> None:
    """Screen every candidate and choose the refits (``st.screening``, ``st.chosen``): the
    observation-level entries best screened first (at most ``max_refits``, above ``screen_min``
    when set), then every forward-level one when ``refit_forward``."""
    o, cand = run.options, st.candidates
    t1 = time.perf_counter()
    run.track.at("screening", steps=len(cand))
    scr = screen(st.problem, st.base, cand, seed=stage_seed(o.seed, "screen"), map=run.map, **(o.screen_options or {}))
    st.n_simulations += sum(int(v["n_simulations"]) for v in scr.values())
    scr["_base"]["wall_s"] = time.perf_counter() - t1
    st.screening = scr
    ranked = sorted((n for n in cand if np.isfinite(scr[n]["score"])), key=lambda n: -scr[n]["score"])
    obs_ranked = [n for n in ranked if not (o.refit_forward and get(n).kind == "forward")]
    chosen = [n for n in obs_ranked if o.screen_min is None or scr[n]["score"] > o.screen_min][: o.max_refits]
    if o.refit_forward:
        chosen += [n for n in cand if get(n).kind == "forward"]
    if not chosen:
        if o.max_refits == 0:
            why = "max_refits=0"
        elif o.screen_min is not None and obs_ranked:
            why = f"no extension raised the best log-likelihood by more than {o.screen_min} nats at the base posterior"
        else:
            why = "no candidate can be evaluated on this recording"
        st.notes.append(f"nothing refitted: {why}")
    st.chosen = chosen
