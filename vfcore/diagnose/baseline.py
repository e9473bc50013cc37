"""The base fit: independent SMC runs of the base model, their between-run error, the escalation when
they disagree, the base fit's summary and its regularity (:ref:`diagnose-pipeline-base-fit`)."""

from __future__ import annotations

import math
import time

import numpy as np

from ..inference.problem import Problem
from .material import material_first, material_sentence
from .seeds import spawn_seed, stage_seed
from .state import DiagnosisState, Run
from .summary import best_particles

__all__ = ["base_fit", "between_run_sd", "fit_base", "check_regularity", "at_noise_floor"]


def between_run_sd(runs) -> float:
    """Monte Carlo error of one SMC log-evidence that its own (delta-method) error misses: the
    part of the observed spread of independent runs of the same model not explained by their
    reported errors, ``sqrt(max(var(log Z_k) - mean(se_k^2), 0))`` (sample variance, ddof = 1).

    The delta-method error ignores the particle dependence and, above all, which mode of a rugged
    likelihood a run settles in (vfcore.inference.smc); two runs of the base model differing by
    tens to thousands of nats measure that directly. It is an *additive* error of every single SMC
    run on this recording (base or extended: the same sampler, the same likelihood), so each fit's
    error becomes ``sqrt(se^2 + tau^2)``. A multiplicative factor instead would scale
    tau by the ratio to a tiny delta-method error and let a 1,000-nat base spread wipe out a
    3,500-nat gain whose extended fit has a delta-method error of 1 nat (measured on a concealed
    case). 0 with fewer than two
    finite runs."""
    z = np.array([p.log_evidence for p in runs], dtype=float)
    se = np.array([p.log_evidence_se for p in runs], dtype=float)
    if z.size < 2 or not (np.all(np.isfinite(z)) and np.all(np.isfinite(se))):
        return 0.0
    return float(math.sqrt(max(np.var(z, ddof=1) - np.mean(se**2), 0.0)))


def base_fit(
    problem: Problem,
    *,
    n_particles: int,
    base_runs: int = 2,
    seed: int = 0,
    map=map,
    chunk_size: int = 40,
    escalate_tau: float | None = 10.0,
    escalate_factor: int = 2,
    runs_out: list | None = None,
    **smc_options,
):
    """The base fit of :func:`diagnose`: ``base_runs`` independent SMC runs (run ``k`` seeded by
    the child ``k`` of ``SeedSequence(seed)``, :func:`.seeds.spawn_seed`), the one with the largest log-evidence kept.

    When the runs disagree beyond their reported errors (between-run error
    :func:`between_run_sd` > ``escalate_tau`` nats) the sampler is hopping between material
    modes on this recording: ``max(2, base_runs)`` more runs are made with ``escalate_factor``
    times the particles, the largest evidence of all runs is kept, and the between-run error is
    taken from the larger runs (the ones later fits are made at). Returns
    ``(base, tau, factor, n_simulations, notes)`` with ``factor`` 1 or ``escalate_factor``.
    ``runs_out``: a list, extended with ``(log Z, se)`` of every run (the best-of-base rule,
    :func:`.rank.rank_best_of_base`).
    """
    from ..inference.smc import WHOLE_RUN_OPTIONS, smc, smc_many

    def best(ps):
        return max(ps, key=lambda p: p.log_evidence if math.isfinite(p.log_evidence) else -math.inf)

    def fmt(ps):
        return ", ".join(f"{p.log_evidence:.1f} +- {p.log_evidence_se:.1f}" for p in ps)

    def made(jobs):
        """The runs ``(particles, seed)``, together (:func:`vfcore.inference.smc.smc_many`: each as alone, one
        batch a round) unless an option only a whole run takes asks for one after another."""
        if set(smc_options) & set(WHOLE_RUN_OPTIONS):
            return [smc(problem, n_particles=n, seed=s, map=map, chunk_size=chunk_size, **smc_options) for n, s in jobs]
        return smc_many(problem, jobs, map=map, chunk_size=chunk_size, **smc_options)

    notes, factor = [], 1
    runs = made([(n_particles, spawn_seed(seed, k)) for k in range(max(1, int(base_runs)))])
    n_sims = sum(int(p.n_simulations) for p in runs)
    tau = between_run_sd(runs)
    if len(runs) > 1:
        notes.append(f"base runs log-evidence: {fmt(runs)}; the largest kept")
    if escalate_tau is not None and len(runs) > 1 and tau > escalate_tau and int(escalate_factor) > 1:
        factor = int(escalate_factor)
        big = made([(n_particles * factor, spawn_seed(seed, k + len(runs))) for k in range(max(2, int(base_runs)))])
        n_sims += sum(int(p.n_simulations) for p in big)
        notes.append(
            f"base runs disagree (between-run error {tau:.1f} nats > {escalate_tau:g}): "
            f"{factor}x particles from here on; larger base runs: {fmt(big)}"
        )
        tau = between_run_sd(big)
        runs = runs + big
    if runs_out is not None:
        runs_out.extend((float(p.log_evidence), float(p.log_evidence_se)) for p in runs)
    return best(runs), tau, factor, n_sims, notes


def _fit(run: Run, problem):
    """``base_fit`` of ``problem`` with the run's settings; returns its tuple and the ``(log Z, se)``
    of every run."""
    o, runs = run.options, []
    out = base_fit(
        problem,
        n_particles=o.n_particles,
        base_runs=o.base_runs,
        seed=stage_seed(o.seed, "base"),
        map=run.map,
        chunk_size=o.chunk_size,
        escalate_tau=o.escalate_tau,
        escalate_factor=o.escalate_factor,
        runs_out=runs,
        **run.smc,
    )
    return (*out, runs)


def fit_base(run: Run, st: DiagnosisState) -> None:
    """Material first (when asked), then the base fit unless one was given, and its summary
    ``st.before``; the escalation factor multiplies the refits' particles from here on."""
    run.track.at("base fit")
    fitted, all_base = None, []
    if run.options.free_material:
        st.problem, st.base, fitted, st.material = material_first(
            st.problem, st.base, lambda pb: _fit(run, pb), rule=run.rule
        )
        m = st.material
        if m is not None:
            st.notes.append(
                "material: "
                + ("the fixed parameters were wrong: " if m["found"] else "")
                + material_sentence(m)
                + ("" if m["found"] else f" ({m['reason']})")
                + f"; the {m['kept']} model is the base from here on"
            )
    if st.base is None:
        fitted = _fit(run, st.problem)
    if fitted is not None:
        st.base, st.tau, factor, nb, bnotes, runs = fitted
        all_base.extend(runs)
        st.n_simulations += nb
        st.notes.extend(bnotes)
        if run.options.escalate_refits:
            st.refit_n *= factor
    else:
        st.n_simulations += int(st.base.n_simulations)
        all_base.append((float(st.base.log_evidence), float(st.base.log_evidence_se)))
        # a stored posterior does not carry its problem's area scale; its residuals need it
        st.base.area_scale = st.problem.area_scale
    st.before = st.summary(st.base)
    st.before["base_runs"] = [[z, s_] for z, s_ in all_base]
    st.before["wall_s"] = time.perf_counter() - run.t0  # all base runs
    st.before["base_simulations"] = st.n_simulations
    _note_noise_scale(st)


def _note_noise_scale(st: DiagnosisState) -> None:
    """A note when the likelihood's nominal noise sd is far from the recording's own."""
    s_hat, pb = st.before["predictive_noise_sd"], st.problem
    if pb.noise == "fixed" and s_hat > 0 and not 2.0 / 3.0 <= pb.sigma_e / s_hat <= 1.5:
        st.notes.append(
            f"the likelihood's noise sd sigma_e = {pb.sigma_e:g} mm^2 is {pb.sigma_e / s_hat:.2g} times "
            f"the recording's noise as estimated from it ({s_hat:.3g} mm^2, second differences of the "
            "base fit's residual): log-likelihood differences scale as 1/sigma_e^2, and the dlogZ "
            "nearly so; 'noise: marginal' integrates sigma_e out instead"
        )


def check_regularity(run: Run, st: DiagnosisState) -> None:
    """The base fit's heaviest particle re-simulated slightly moved (:mod:`.regularity`): its
    largest log-likelihood change is the roughness the local check counts as an error."""
    if not run.options.regularity_check:
        return
    from . import regularity

    run.track.at("regularity check")
    sens = regularity.sensitivity(
        st.problem, best_particles(st.base, 1)[0], seed=stage_seed(run.options.seed, "regularity")
    )
    st.n_simulations += sens.n_simulations
    st.before["regularity"] = sens.to_dict()
    st.roughness = sens.max_change  # inf when a perturbed run failed
    if sens.irregular:
        st.notes.append(
            f"the base fit's vibration is irregular: a relative change of {sens.step:g} in its "
            f"parameters changes the log-likelihood by up to {sens.max_change:.1f} nats, so the "
            "waveform likelihood is a rough function of the parameters here and log-evidences carry "
            "the luck of the simulated points (the between-run error measures part of it); the local "
            "check counts that change as an error of its comparison"
        )
    elif sens.rough:
        st.notes.append(
            f"the base fit's likelihood is rough: {regularity.rough_phrase(sens.to_dict())}; the base "
            "posterior is a staircase at its own scale, so its evidence, and every dlogZ against it, "
            "carries the luck of the simulated points beyond the quoted errors (docs/inference.md, "
            "'Aperiodic vibration')"
        )


def at_noise_floor(run: Run, st: DiagnosisState) -> bool:
    """Whether the base fit is so close to the recording's noise that no fit could lower its RMS by
    ``min_rms_gain`` (no fit goes below the noise), so nothing could be named; notes why."""
    o, b = run.options, st.before
    s_hat = b["predictive_noise_sd"]
    floor = 1.0 - s_hat / b["residual_rms"] if b["residual_rms"] > 0 else 0.0
    if not (o.floor_stop and math.isfinite(floor) and floor < o.min_rms_gain):
        return False
    st.notes.append(
        f"the base fit leaves a residual RMS of {b['residual_rms']:.3g} mm² against a noise of "
        f"{s_hat:.3g} mm²: no extension could lower it by {100 * o.min_rms_gain:.0f} % (at most "
        f"{100 * max(floor, 0.0):.0f} %), so none was screened or refitted"
    )
    return True
