"""The checks made before a winner is named (:ref:`diagnose-naming`): the base model re-fitted in
a candidate's material mode (mode check; the gain may be the mode, not the physics), the local
comparison with that fit when only the between-run error swamps a gain, and the nested check of a
winner that sits where it reduces to a simpler catalogue entry."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from .amend import local_passes, prefer_nested, promote_local
from .continuation import search_base
from .extensions import get
from .fit import null_drops, param_table
from .mode_fits import base_near
from .rank import RankReport, null_consistent
from .refits import keep_if_higher
from .seeds import stage_seed
from .state import DiagnosisState, Run

__all__ = ["mode_check", "local_check", "nested_check"]

#: A ranking of the state's fits (:mod:`.naming`): the rule with the between-run error or best of base.
Ranker = Callable[[Run, DiagnosisState], RankReport]


def mode_check(run: Run, st: DiagnosisState, name: str) -> dict:
    """Refit the base model around ``name``'s material mode; its evidence bound joins the references
    (returns the summary, also kept in ``st.before["mode_checks"]``)."""
    o = run.options
    t1 = time.perf_counter()
    run.track.at("mode check", name)
    zb, sb, near = base_near(
        st.problem,
        st.refits[name],
        n_particles=st.refit_n,
        seed=stage_seed(o.seed, "mode_check", len(st.before.get("mode_checks", {}))),
        map=run.map,
        chunk_size=o.chunk_size,
        **run.smc,
    )
    st.n_simulations += int(near.n_simulations)
    sn = st.summary(near)
    sn.update(
        wall_s=time.perf_counter() - t1,
        log_evidence_bound=zb,
        log_evidence_bound_se=sb,
        box=near.info["box"],
        log_box_probability=near.info["log_box_probability"],
    )
    st.before.setdefault("mode_checks", {})[name] = sn
    st.references[f"base near {name}"] = (zb, math.hypot(sb, st.tau), sn["residual_rms"])
    found = st.refits[name].info.get("continuation")  # set only by a kept continued fit
    if found is not None:
        _continued_mode_check(run, st, name, found)
    return sn


def _continued_mode_check(run: Run, st: DiagnosisState, name: str, found: dict) -> None:
    """The base model searched by window continuation from ``name``'s continued optimum (its own
    parameters dropped), with the settings ``name``'s search had, and fitted from there: the base
    gets the search the entry got, so a mode the entry's search found is not named as physics."""
    start = np.array([found["params"][n] for n in st.problem.prior.names], dtype=float)
    sd = stage_seed(run.options.seed, "mode_check_continued", len(st.before.get("mode_checks", {})))
    copts = {**(run.options.continuation_options or {}), "n_design": 0}
    got = search_base(run, st, start[None, :], sd, f"{name} continued", copts)
    if got is not None:
        fb, zc, sc, _ = got
        st.notes.append(
            f"mode check: the base model searched from {name}'s continued optimum (best "
            f"log-likelihood {fb.loglik:.1f}) and fitted from there: log Z = {zc:.1f} +- {sc:.1f}"
        )


def local_check(run: Run, st: DiagnosisState, ranking: RankReport, checked: set, ranker: Ranker):
    """A candidate that fails ONLY because the between-run error swamps its gain (base runs in
    different modes) is compared with the base model refitted in its own mode, the roughness
    counted as an error. Returns ``(ranking, local)``, ``local = (name, dlogZ, se)`` when it was
    named on that comparison, else None."""
    o = run.options
    cands = [r for r in ranking.rows if r.fails_only_on_error(o.min_gain, o.min_rms_gain) and r.name not in checked]
    if not cands:
        return ranking, None
    name = cands[0].name  # rows are sorted by delta
    sn = mode_check(run, st, name)
    ranking = ranker(run, st)
    post = st.refits[name]
    d_loc = float(post.log_evidence) - sn["log_evidence_bound"]
    passes, se_loc = local_passes(
        d_loc, float(post.log_evidence_se), sn["log_evidence_bound_se"], st.roughness, min_gain=o.min_gain, k_se=o.k_se
    )
    sn["local"] = {"candidate": name, "dlogZ": d_loc, "se": se_loc, "roughness": st.roughness}
    row = next(r for r in ranking.rows if r.name == name)
    if ranking.winner is None and passes and row.fails_only_on_error(o.min_gain, o.min_rms_gain):
        return promote_local(ranking, name, d_loc, se_loc, st.tau), (name, d_loc, se_loc)
    return ranking, None


def nested_check(run: Run, st: DiagnosisState, ranking: RankReport, local, ranker: Ranker) -> RankReport:
    """The winner ``w`` sitting where it reduces to a simpler entry (``Extension.nests``): that entry
    refitted in ``w``'s material mode, and named instead when within ``k_se`` errors of ``w``."""
    o = run.options
    w = ranking.winner
    names, mean, sd = param_table(st.refits[w])
    for simpler, restrict in get(w).nests:
        if simpler not in st.candidates:
            continue
        if not null_consistent(
            names, mean, sd, w, o.null_sd, only=restrict, drops=null_drops(st.refits[w]), by_drop=True
        ):
            continue
        t1 = time.perf_counter()
        run.track.at("nested check", simpler)
        zb, sb, near = base_near(
            st.problem,
            st.refits[w],
            n_particles=st.refit_n,
            seed=stage_seed(o.seed, "nested_check"),
            map=run.map,
            chunk_size=o.chunk_size,
            extension=simpler,
            integrate=o.integrate,
            **run.smc,
        )
        st.n_simulations += int(near.n_simulations)
        # zb: a lower bound on the simpler model's evidence
        if keep_if_higher(run, st, simpler, near, zb, t1, box_refit_of=w) is not None:
            st.after[simpler]["box_refit_of"] = w
        ranking = ranker(run, st)
        if local is not None and ranking.winner is None:  # the winner was named on the local comparison
            ranking = promote_local(ranking, *local, st.tau)
        ranking.notes.append(
            f"nested check: {w} sits where it reduces to {simpler}; {simpler} refitted in "
            f"{w}'s material mode: log Z >= {zb:.1f} +- {sb:.1f}"
        )
        rs = next((r for r in ranking.rows if r.name == simpler), None)
        if ranking.winner == simpler or rs is None:
            return ranking
        preferred = _prefer_simpler(run, st, ranking, w, simpler, restrict, (zb, sb), rs)
        if preferred is not None:
            return preferred
    return ranking


def _prefer_simpler(
    run: Run, st: DiagnosisState, ranking: RankReport, w: str, simpler: str, restrict, bound, rs
) -> RankReport | None:
    """``simpler`` named instead of ``w`` when within ``k_se`` delta-method errors of it (both fits sit
    in one material mode: no between-run error, as in the local check) and found or failing only on
    the error; None otherwise (the next simpler entry is tried)."""
    o = run.options
    names, mean, sd = param_table(st.refits[w])
    idx = {n: i for i, n in enumerate(names)}
    zb, sb = bound
    gap = float(st.refits[w].log_evidence) - float(st.refits[simpler].log_evidence)
    se = math.hypot(float(st.refits[w].log_evidence_se), float(st.refits[simpler].log_evidence_se))
    if ranking.winner == w and gap <= o.k_se * se and (rs.found or rs.fails_only_on_error(o.min_gain, o.min_rms_gain)):
        desc = ", ".join(f"{n} {float(mean[idx[n]]):.3g} +- {float(sd[idx[n]]):.2g}" for n in restrict)
        return prefer_nested(
            ranking,
            simpler,
            w,
            (
                f"{simpler}: named instead of {w}, whose fit sits where it reduces to {simpler} ({desc}); "
                f"{simpler} refitted in that material mode: log Z >= {zb:.1f} +- {sb:.1f}, against {w}'s "
                f"{float(st.refits[w].log_evidence):.1f} (difference {gap:.1f} +- {se:.1f}), with fewer parameters"
            ),
        )
    return None
