"""Name the missing physics: rank extended fits against the base fit by log-evidence gain.

For the base fit (log Z_0 +- s_0) and an extended fit (log Z_e +- s_e), run independently,
``d = log Z_e - log Z_0`` with Monte Carlo standard error ``se = sqrt(s_0^2 + s_e^2)``.
Decision rule: an extension is *found* when ``d > min_gain`` (3 nats, i.e. a Bayes factor
> e^3 ~ 20, "strong" on the Kass & Raftery 1995 scale) **and** ``d > k_se * se`` (k_se = 3: the
gain is not Monte Carlo noise). The evidence already charges each extra parameter for its prior
volume (Occam factor), so no separate parameter penalty is added. Among found extensions the one
with the largest ``d`` is named; when none qualifies the verdict is "no missing physics found".

Beside the evidence, each candidate can carry the fraction of the *localised* residual it
removes: ``1 - E_after / E_before`` with ``E`` the residual energy (sum of squares) in the phase
where the base fit's residual is concentrated (:func:`residual_removed`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

NO_FINDING = "no missing physics found"


def _lz(x) -> tuple[float, float]:
    """(log_evidence, se) from a Posterior-like object, a (value, se) pair or a dict."""
    if hasattr(x, "log_evidence"):
        return float(x.log_evidence), float(getattr(x, "log_evidence_se", math.nan))
    if isinstance(x, dict):
        return float(x["log_evidence"]), float(x.get("log_evidence_se", math.nan))
    v, s = x
    return float(v), float(s)


def residual_removed(before, after, phase: str | None = None) -> float:
    """Fraction of the residual energy in ``phase`` (default: ``before.dominant_phase``) that the
    extended fit removes, from two :class:`.locate.LocateReport` computed on the same observation.
    Negative when the extension makes that phase worse."""
    phase = phase or before.dominant_phase
    if phase is None:
        return math.nan
    eb = before.phase_rms[phase] ** 2 * before.n_samples[phase]
    ea = after.phase_rms[phase] ** 2 * after.n_samples[phase]
    return float(1.0 - ea / eb) if eb > 0 else math.nan


@dataclass(frozen=True)
class CandidateRow:
    name: str
    log_evidence: float
    log_evidence_se: float
    delta: float
    delta_se: float
    n_extra: int | None
    residual_removed: float
    found: bool


@dataclass
class RankReport:
    base_log_evidence: float
    base_log_evidence_se: float
    rows: list[CandidateRow]               # sorted by delta, largest first
    winner: str | None
    min_gain: float
    k_se: float
    notes: list[str] = field(default_factory=list)

    @property
    def verdict(self) -> str:
        if self.winner is None:
            return NO_FINDING
        r = next(r for r in self.rows if r.name == self.winner)
        return (f"missing physics: {self.winner} (dlogZ = {r.delta:.2f} +- {r.delta_se:.2f}"
                + (f", removes {100 * r.residual_removed:.0f} % of the localised residual"
                   if math.isfinite(r.residual_removed) else "") + ")")

    def table(self) -> list[dict]:
        return [r.__dict__.copy() for r in self.rows]


def rank_extensions(base, candidates: dict, *, residual: dict | None = None, n_extra: dict | None = None,
                    min_gain: float = 3.0, k_se: float = 3.0) -> RankReport:
    """Rank candidate extended fits against ``base``.

    Parameters
    ----------
    base : Posterior-like (``log_evidence``, ``log_evidence_se``), ``(logZ, se)`` or dict.
    candidates : name -> same kinds as ``base`` (each an independent fit of the extended model).
    residual : name -> fraction of the localised residual removed (:func:`residual_removed`).
    n_extra : name -> number of extra parameters (reported only).
    """
    z0, s0 = _lz(base)
    rows, notes = [], []
    for name, c in candidates.items():
        z, s = _lz(c)
        d = z - z0
        se = math.sqrt((s0 if math.isfinite(s0) else math.inf) ** 2 + (s if math.isfinite(s) else math.inf) ** 2)
        if not math.isfinite(se):
            notes.append(f"{name}: no Monte Carlo error for the log-evidence; cannot be declared found")
        found = bool(math.isfinite(d) and math.isfinite(se) and d > min_gain and d > k_se * se)
        rows.append(CandidateRow(name, z, s, d, se, None if n_extra is None else n_extra.get(name),
                                 float((residual or {}).get(name, math.nan)), found))
    rows.sort(key=lambda r: -r.delta if math.isfinite(r.delta) else math.inf)
    winner = next((r.name for r in rows if r.found), None)
    return RankReport(z0, s0, rows, winner, min_gain, k_se, notes)


def compare_fits(base_post, ext_posts: dict, *, min_gain: float = 3.0, k_se: float = 3.0) -> RankReport:
    """:func:`rank_extensions` from fitted posteriors carrying predictions: the localised residual
    fraction is computed with :func:`.locate.locate` on each posterior's predictive ensemble."""
    from .locate import locate

    def rep(p):
        rp = p.resampled_predictive()
        g = np.asarray(rp.gaw, dtype=float)[np.asarray(rp.ok, dtype=bool)]
        return locate(np.asarray(p.obs_gaw, dtype=float)[: g.shape[1]], g, p.fps)

    r0 = rep(base_post)
    res = {n: residual_removed(r0, rep(p)) for n, p in ext_posts.items()}
    nx = {n: len(p.names) - len(base_post.names) for n, p in ext_posts.items()}
    return rank_extensions(base_post, ext_posts, residual=res, n_extra=nx, min_gain=min_gain, k_se=k_se)
