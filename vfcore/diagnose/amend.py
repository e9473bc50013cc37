"""Amend a ranking after the checks: the rules that name another winner than the evidence ranking of
:func:`.rank.rank_extensions` did (:ref:`diagnose-naming`) -- a candidate found on the local
comparison, the simpler of two nested entries, the simpler of two explanations the evidence cannot tell
apart -- and the local check's evidence test. Each returns a new :class:`.rank.RankReport`; the one given
is left as it was.
"""

from __future__ import annotations

import dataclasses as dc
import math

from .rank import RankReport


def promote_local(ranking: RankReport, name: str, d_local: float, se_local: float, tau: float) -> RankReport:
    """``ranking`` with ``name`` found on the *local* comparison (:ref:`diagnose-naming`):
    a candidate that met every criterion except ``d > k_se * se`` with the between-run error
    ``tau`` in ``se`` is named when it beats the base model refitted in its own material mode
    (:func:`.mode_fits.base_near`) by ``d_local`` > ``k_se`` local errors ``se_local`` (delta-method
    errors of the two fits, no ``tau``: both sit in one mode, so the mode hopping that ``tau``
    measures is not part of this comparison) and still beats every base-model fit found."""
    named = _named(
        ranking,
        name,
        (
            f"{name}: named on the local comparison: dlogZ {d_local:.1f} +- {se_local:.1f} against the base model "
            f"refitted in its material mode (the global error includes a between-run error of {tau:.1f} nats from "
            f"base runs that landed in different modes)"
        ),
    )
    return dc.replace(named, local=(float(d_local), float(se_local)))


def local_passes(
    d_local: float,
    se_refit: float,
    se_bound: float,
    roughness: float = 0.0,
    *,
    min_gain: float = 3.0,
    k_se: float = 3.0,
) -> tuple[bool, float]:
    """The evidence test of the local check: ``(passes, se)`` with ``se`` the delta-method errors of
    the refit and of the base refitted in its mode, and the likelihood's ``roughness`` at the base
    fit (:func:`.regularity.sensitivity`; 0 for a regular vibration), in quadrature. On an
    irregular likelihood there is no smooth local mode for the two fits to share, and how far the
    log-likelihood jumps between neighbouring points is an error of their comparison (a concealed
    leak at high p_sub: +1,426 +- 0.8 locally, at a roughness of 81,000 nats; :ref:`diagnose`
    section 4, "Regularity")."""
    se = math.hypot(float(se_refit), float(se_bound), float(roughness))
    ok = math.isfinite(d_local) and math.isfinite(se) and d_local > min_gain and d_local > k_se * se
    return bool(ok), se


def prefer_nested(ranking: RankReport, simpler: str, richer: str, note: str) -> RankReport:
    """``ranking`` with ``simpler`` named instead of ``richer``: the richer winner's fit sits where
    it reduces to the simpler entry (``Extension.nests``) and the simpler model, refitted in the
    same material mode, is within the errors of it (:ref:`diagnose-naming`: nested check).
    The same fit quality with fewer parameters is the better explanation (Occam; the evidence
    would say so too had the simpler model's own SMC found the mode)."""
    return _named(ranking, simpler, note)


def prefer_parsimonious(ranking: RankReport, k: float = 1.0) -> RankReport:
    """``ranking`` with the winner replaced by a found extension with fewer parameters whose
    log-evidence is within ``k`` standard errors of the winner's (``se``: both fits' errors in
    quadrature, the reference cancels): the one-standard-error rule of model selection (Breiman
    et al. 1984, *Classification and Regression Trees* section 3.4.3; Hastie, Tibshirani &
    Friedman, *Elements of Statistical Learning* 2nd ed. section 7.10). When the evidence cannot
    tell two explanations apart, the one with fewer free parameters is named and the other is
    reported as a rival. Among several, the fewest parameters, then the largest evidence.
    ``k <= 0`` or no winner: unchanged."""
    if ranking.winner is None or not k > 0:
        return ranking
    w = next(r for r in ranking.rows if r.name == ranking.winner)
    if w.n_extra is None:
        return ranking
    best = None
    for r in ranking.rows:
        if r.name == w.name or not r.found or r.n_extra is None or r.n_extra >= w.n_extra:
            continue
        gap, se = w.delta - r.delta, math.hypot(w.log_evidence_se, r.log_evidence_se)
        if not (math.isfinite(gap) and math.isfinite(se) and gap <= k * se):
            continue
        if best is None or (r.n_extra, -r.delta) < (best.n_extra, -best.delta):
            best = r
    if best is None:
        return ranking
    gap, se = w.delta - best.delta, math.hypot(w.log_evidence_se, best.log_evidence_se)
    return _named(
        ranking,
        best.name,
        (
            f"{best.name} ({best.n_extra} parameter{'s' if best.n_extra != 1 else ''}) named instead of {w.name} "
            f"({w.n_extra}): log-evidence {gap:.1f} +- {se:.1f} below it, within {k:g} standard error"
            f"{'s' if k != 1 else ''} (one-standard-error rule: the simpler explanation)"
        ),
    )


def _named(ranking: RankReport, name: str, note: str) -> RankReport:
    """A copy of ``ranking`` with ``name``'s row found, ``name`` the winner and ``note`` added."""
    rows = [dc.replace(r, found=True, reason="") if r.name == name else r for r in ranking.rows]
    return dc.replace(ranking, rows=rows, winner=name, notes=list(ranking.notes) + [note], local=None)
