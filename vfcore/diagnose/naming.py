"""Naming: the refits ranked against the base fit (:mod:`.rank`), with the mode checks, the local
check, the best-of-all-base-fits rule and the nested check (:mod:`.checks`) run as their triggers
fire, and the one-standard-error preference last (:ref:`diagnose-naming`)."""

from __future__ import annotations

import dataclasses

from .amend import prefer_parsimonious
from .checks import local_check, mode_check, nested_check
from .extensions import get
from .rank import RankReport, rank_best_of_base, rank_extensions
from .state import DiagnosisState, Run

__all__ = ["rank_state", "best_of_base_from_summaries", "rank_best_of_base_state", "name_winner"]


def rank_state(run: Run, st: DiagnosisState) -> RankReport:
    """:func:`.rank.rank_extensions` of the state's refits against its base fit and references, every
    error with the between-run error in quadrature."""
    after, refits = st.after, st.refits
    return rank_extensions(
        st.lz(st.base),
        {n: st.lz(p) for n, p in refits.items()},
        residual={n: after[n]["residual_removed"] for n in after},
        n_extra={n: len(get(n).params) for n in refits},
        rms={n: after[n]["residual_rms"] for n in after},
        base_rms=st.before["residual_rms"],
        null={n: after[n]["null_consistent"] for n in after},
        references=st.references,
        **run.rule,
    )


def rank_best_of_base_state(run: Run, st: DiagnosisState) -> RankReport:
    """:func:`best_of_base_from_summaries` of the state's summaries."""
    return best_of_base_from_summaries(st.before, st.after, **run.rule)


def best_of_base_from_summaries(before: dict, after: dict, **rule) -> RankReport:
    """:func:`.rank.rank_best_of_base` on a diagnosis' summaries: ``before`` (a report's ``"base"``:
    the base fit's log-evidence and residual RMS, its ``"base_runs"`` and ``"mode_checks"``) and
    ``after`` (its ``"refits"``, each with log-evidence, residual RMS, localised residual removed and
    the null check). The pipeline names with it, and a kept report can be decided again with it
    (everything it reads is in the report). ``rule``: ``min_gain``, ``k_se``, ``min_rms_gain``."""
    return rank_best_of_base(
        (before["log_evidence"], before["log_evidence_se"]),
        {n: (v["log_evidence"], v["log_evidence_se"]) for n, v in after.items()},
        base_runs=before.get("base_runs") or [(before["log_evidence"], before["log_evidence_se"])],
        mode_checks={
            k: (v["log_evidence_bound"], v["log_evidence_bound_se"], v["residual_rms"])
            for k, v in before.get("mode_checks", {}).items()
        },
        residual={n: v["residual_removed"] for n, v in after.items()},
        n_extra={n: len(get(n).params) for n in after},
        rms={n: v["residual_rms"] for n, v in after.items()},
        base_rms=before["residual_rms"],
        null={n: v["null_consistent"] for n, v in after.items()},
        **rule,
    )


def name_winner(run: Run, st: DiagnosisState) -> RankReport:
    """The ranking the report gives: mode checks of each winner in turn (at most ``mode_checks``),
    the local check, best of all base fits on an irregular base, the nested check, parsimony; the
    ranking's notes join the state's."""
    o = run.options
    ranking, checked = rank_state(run, st), set()
    while ranking.winner is not None and ranking.winner not in checked and len(checked) < max(0, int(o.mode_checks)):
        checked.add(ranking.winner)
        mode_check(run, st, ranking.winner)
        ranking = rank_state(run, st)
    local = None
    if ranking.winner is None and o.local_check and st.tau > 0:
        ranking, local = local_check(run, st, ranking, checked, rank_state)
    ranker = rank_state
    irregular = bool(st.before.get("regularity", {}).get("irregular", False))
    if ranking.winner is None and o.best_of_base and irregular:
        ranking = _best_of_base(run, st)
        if ranking.winner is not None:
            ranker = rank_best_of_base_state
    if ranking.winner is not None and o.nested_check:
        ranking = nested_check(run, st, ranking, local, ranker)
    ranking = prefer_parsimonious(ranking, o.parsimony_se)
    st.notes.extend(ranking.notes)
    return ranking


def _best_of_base(run: Run, st: DiagnosisState) -> RankReport:
    """Best of all base fits: on an irregular base fit, where the base runs' scatter swamped every
    gain, each entry compared with the best base-model fit by its own errors; a winner gets a mode
    check of its own material mode first (at most two), and is not named without one."""
    mode_checks = int(run.options.mode_checks)
    ranking = rank_best_of_base_state(run, st)
    tried = set(st.before.get("mode_checks", {}))
    for _ in range(2 if mode_checks > 0 else 0):
        if ranking.winner is None or ranking.winner in tried:
            break
        tried.add(ranking.winner)  # the winner's own material mode, re-fitted with the base model
        mode_check(run, st, ranking.winner)
        ranking = rank_best_of_base_state(run, st)
    if ranking.winner is not None and mode_checks > 0 and ranking.winner not in tried:
        ranking.notes.append(
            f"{ranking.winner}: best of all base fits, but its material mode was not "
            "re-fitted with the base model within two mode checks; not named"
        )
        w = ranking.winner
        ranking = dataclasses.replace(
            ranking,
            winner=None,
            rows=[
                dataclasses.replace(r, found=False, reason="best of all base fits: material mode not re-fitted")
                if r.name == w
                else r
                for r in ranking.rows
            ],
        )
    return ranking
