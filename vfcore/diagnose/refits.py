"""The refits: every chosen entry fitted by SMC with the base model's likelihood (base + extension
parameters; :ref:`diagnose-pipeline-refit`), each summarised against the base fit, and the rule by
which a later fit of an entry (rescue, shared mode, continuation, nested check) replaces its first."""

from __future__ import annotations

import math
import time

from ..inference.posterior import Posterior
from ..inference.smc import WHOLE_RUN_OPTIONS
from .extensions import get
from .fit import fit_extended, null_drops, param_table
from .locate import locate
from .mode_fits import base_reference, referenced
from .rank import null_consistent, residual_removed
from .seeds import stage_seed
from .state import DiagnosisState, Run
from .summary import predicted_gaws
from .together import fit_extended_many

__all__ = ["refit_chosen", "starts_from_base", "summarise", "keep_if_higher"]


def starts_from_base(refit_start: str, name: str) -> bool:
    """Whether entry ``name``'s refit starts from the base posterior under ``refit_start``
    (``DiagnoseOptions.refit_start``): every entry's with ``"base"``, the observation-level entries'
    with ``"mixed"`` (a forward-level entry changes the dynamics, and its mode may lie far from the
    base's materials), none with ``"prior"``."""
    return refit_start == "base" or (refit_start == "mixed" and get(name).kind != "forward")


def refit_chosen(run: Run, st: DiagnosisState) -> None:
    """An SMC fit of every chosen entry (``st.refits``, summaries in ``st.after``), all run together
    (:func:`.together.fit_extended_many`: each fit as alone, every generation of every entry in one
    batch); with SMC options that only a whole run takes (``vfcore.inference.smc.WHOLE_RUN_OPTIONS``), one after
    another. A summary's ``wall_s`` is the time from the stage's start to its fit's end."""
    o, pb = run.options, st.problem
    g = predicted_gaws(st.base)
    st.base_loc = locate(pb.obs_compared[: g.shape[1]], g, pb.fps)
    seeds = [stage_seed(o.seed, "refit", i) for i in range(len(st.chosen))]
    smc = run.smc
    if st.chosen and not set(smc) & set(WHOLE_RUN_OPTIONS):
        t1 = time.perf_counter()
        run.track.at("refit", st.chosen[0] if len(st.chosen) == 1 else "entries", 1, 1)
        ends: dict[int, float] = {}
        refs = {
            name: base_reference(pb, st.base, name, o.rescue_inflate, o.integrate, sd)
            for name, sd in zip(st.chosen, seeds)
            if starts_from_base(o.refit_start, name)
        }
        jobs = [
            (name, st.refit_n, sd) + (({"reference": refs[name]},) if name in refs else ())
            for name, sd in zip(st.chosen, seeds)
        ]
        posts = fit_extended_many(
            pb,
            jobs,
            map=run.map,
            chunk_size=o.chunk_size,
            integrate=o.integrate,
            on_done=lambda i, _: ends.setdefault(i, time.perf_counter()),
            **smc,
        )
        for i, (name, post) in enumerate(zip(st.chosen, posts)):
            if name in refs:
                post = referenced(post, refs[name], o.rescue_inflate)[2]
                post.info["reference_refit_of"] = "base"
            st.refits[name] = post
            st.n_simulations += int(post.n_simulations)
            st.after[name] = summarise(run, st, name, post, t1)
            st.after[name]["wall_s"] = ends[i] - t1
    else:
        for i, name in enumerate(st.chosen):
            t1 = time.perf_counter()
            run.track.at("refit", name, i + 1, len(st.chosen))
            post = fit_extended(
                pb,
                name,
                n_particles=st.refit_n,
                seed=seeds[i],
                map=run.map,
                chunk_size=o.chunk_size,
                integrate=o.integrate,
                **smc,
            )
            st.refits[name] = post
            st.n_simulations += int(post.n_simulations)
            st.after[name] = summarise(run, st, name, post, t1)
    if st.tau > 0.0:
        st.notes.append(
            f"between-run Monte Carlo error of a log-evidence: {st.tau:.2f} nats (spread of the "
            "independent base runs beyond their reported errors), added in quadrature to every fit's "
            "error"
        )


def summarise(run: Run, st: DiagnosisState, name: str, post: Posterior, t1: float) -> dict:
    """The summary of a fit of entry ``name`` (:func:`.summary.fit_summary`) with what the naming
    rule reads: the localised residual removed, the RMS improvement on the base fit, whether its
    parameters sit at their null value; ``t1``: when the fit started (``time.perf_counter``)."""
    pb = st.problem
    s = st.summary(post)
    g = predicted_gaws(post)
    s["residual_removed"] = residual_removed(st.base_loc, locate(pb.obs_compared[: g.shape[1]], g, pb.fps))
    s["rms_improvement"] = 1.0 - s["residual_rms"] / st.before["residual_rms"]
    s["null_consistent"] = null_consistent(*param_table(post), name, run.options.null_sd, drops=null_drops(post))
    s["wall_s"] = time.perf_counter() - t1
    s["n_generations"] = int(post.info.get("n_generations", 0))
    return s


def keep_if_higher(
    run: Run, st: DiagnosisState, name: str, near: Posterior, zb: float, t1: float, record: tuple | None = None, **tag
) -> dict | None:
    """A second fit ``near`` of entry ``name`` (log-evidence or its lower bound ``zb``) replaces the
    first when ``zb`` is higher (or the first has none): its evidence is set to ``zb``, ``tag`` goes
    into its ``info``, and its summary into ``st.after``. ``record = (key, dict)``: written to the
    new summary under ``key``, with the first fit's evidence (``"first"``) and its rescue record
    carried over. Returns the first fit's summary when replaced (``{}`` if there was none), ``None``
    when the first is kept."""
    first = st.refits.get(name)
    z1 = float(first.log_evidence) if first is not None else math.nan
    if not math.isfinite(zb) or (math.isfinite(z1) and zb <= z1):
        return None
    near.log_evidence = zb
    near.info.update(tag)
    prev = st.after.get(name, {})
    st.refits[name] = near
    st.after[name] = summarise(run, st, name, near, t1)
    if record is not None:
        key, extra = record
        st.after[name][key] = {
            **extra,
            "first": None
            if first is None
            else {
                "log_evidence": z1,
                "log_evidence_se": float(first.log_evidence_se),
                "n_simulations": int(first.n_simulations),
            },
            **({"rescued": prev["rescued"]} if "rescued" in prev else {}),
        }
    return prev
