"""Name the missing physics: rank extended fits against the base fit by log-evidence gain,
effect size and a null-value check.

For the reference fit (log Z_0 +- s_0; normally the base fit, see below) and an extended fit
(log Z_e +- s_e), run independently, ``d = log Z_e - log Z_0`` with Monte Carlo standard error
``se = sqrt(s_0^2 + s_e^2)``. An extension is *found* when all of:

1. **evidence**: ``d > min_gain`` (3 nats, a Bayes factor > e^3 ~ 20, "strong" on the Kass &
   Raftery 1995 scale) and ``d > k_se * se`` (k_se = 3: the gain is not Monte Carlo noise). The
   evidence already charges each extra parameter for its prior volume (Occam factor).
2. **effect size**: its residual RMS is at least ``min_rms_gain`` (30 %) below the reference
   fit's: ``1 - rms_e / rms_0 >= min_rms_gain``. With hundreds of frames the evidence alone
   calls a 1-10 % improvement "decisive" (measured on concealed-effect cases: a scale case with
   10 % and an asymmetry case named leak with 4 %); the specification asks every named effect to
   remove >= 30 % of the residual RMS. Applied whenever ``rms`` is given (the pipeline always gives it).
3. **not at its null value**: an extended fit whose extension parameters all sit at their null
   value (``ExtParam.null``: the value at which the extension *is* the base model) within
   ``null_sd`` posterior standard deviations has not used the extension; its evidence gain comes
   from a better mode of the *material* parameters, which the base SMC missed.

**Reference raised by null fits.** The extended model at the null value is the base model, so a
null-consistent extended fit is a fit of the base model in the mode it found, with an extra Occam
factor <= 1: ``log Z_e <= log Z_base(that mode)`` approximately. Its log-evidence is therefore a
(conservative) estimate of the base evidence, and the reference becomes the null-consistent fit
with the largest log Z when it beats the base fit (residual RMS of that fit likewise). Every gain
is then measured against the best base-model fit found by any run, so a refit cannot win by
finding the material mode alone. ``references`` adds further base-model estimates: the pipeline
re-runs the base fit on a small box of the prior around the would-be winner's material
posterior (:func:`.mode_fits.base_near`), whose evidence times the box's prior probability is a
lower bound on the base evidence (the likelihood is >= 0 outside the box).

Among found extensions the one with the largest ``d`` is named; when none qualifies the verdict
is "no missing physics found". Each candidate also carries the fraction of the *localised*
residual it removes: ``1 - E_after / E_before`` with ``E`` the residual energy (sum of squares)
in the phase where the base fit's residual is concentrated (:func:`residual_removed`).
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


def null_consistent(
    names, mean, sd, extension, null_sd: float = 2.0, only=None, drops=None, by_drop: bool = False
) -> bool:
    """Whether a fit of ``extension`` (an :class:`.extensions.Extension` or its name) puts every
    extension parameter that has a null value (``ExtParam.null``) within ``null_sd`` posterior
    standard deviations of it. ``names``/``mean``/``sd``: the posterior's parameter names, means
    and standard deviations. ``False`` for an extension with no null value in its prior.

    Two sd, not one: at a null on the prior's bound (leak 0, phase 0) a posterior piled up against
    the bound has mean ~1.3 sd away from it (half-normal), and one sd would call it non-null; an
    unidentified parameter (posterior ~ prior, uniform) has |mean - bound| = 1.73 sd.
    ``only``: test these parameters only (the nested check's restricting parameters).

    ``drops``: name -> median log-likelihood drop at the null value of an integrated parameter
    (:func:`.fit.null_drops`). The mean +- sd test is a normal approximation; it also passes a
    posterior with two modes on either side of the null (the lag of ``lr_stiffness`` at equal
    stiffness: the folds can be swapped, so +lag and -lag fit alike and 0 lies between). A
    parameter whose null is more than ``2 null_sd^2`` nats below the best (``null_sd``
    = 2: 8 nats, the drop of a Gaussian 4 sd out; within 2 sd it is at most 2 nats) is therefore
    not null-consistent, whatever its mean and sd.

    ``by_drop=True``: a parameter with a measured drop is judged by the drop alone (null-consistent
    when it is at most ``2 null_sd^2`` nats), whatever its mean and sd. The nested check's gate
    uses it: there the refit of the simpler entry, not this test, decides, and a parameter pinned
    a few sd from its null can still cost less likelihood at the null (an asymmetry fit of a concealed
    recording: a phase difference 0.012 +- 0.004 cycles, 2.7 sd, whose null costs 2.2 nats) than its Occam factor
    (~ log(prior width / posterior width), 3 nats there) buys back."""
    from .extensions import get

    ext = get(extension) if isinstance(extension, str) else extension
    idx = {n: i for i, n in enumerate(names)}
    checked = False
    for p in ext.params:
        if p.null is None or (only is not None and p.name not in only):
            continue
        if p.name not in idx:
            return False
        i = idx[p.name]
        m, s_ = float(mean[i]), float(sd[i])
        if not (math.isfinite(m) and math.isfinite(s_)):
            return False
        has_drop = drops is not None and p.name in drops and math.isfinite(float(drops[p.name]))
        if not (by_drop and has_drop) and abs(m - p.null) > null_sd * s_:
            return False
        if has_drop and float(drops[p.name]) > 2.0 * null_sd**2:
            return False
        checked = True
    return checked


def residual_removed(before, after, phase: str | None = None) -> float:
    """Fraction of the residual energy in ``phase`` (default: ``before.dominant_phase``) that the
    extended fit removes, from two :class:`.locate.LocateReport` computed on the same observation.
    ``phase`` :data:`.locate.SPREAD` ("whole cycle") takes the energy of every classified sample.
    Negative when the extension makes that phase worse."""
    phase = phase or before.dominant_phase
    if phase is None:
        return math.nan
    eb, ea = _phase_energy(before, phase), _phase_energy(after, phase)
    return float(1.0 - ea / eb) if eb > 0 else math.nan


def _phase_energy(rep, phase: str) -> float:
    from .locate import PHASES, SPREAD

    phases = PHASES if phase == SPREAD else (phase,)
    return float(sum(rep.phase_rms[p] ** 2 * rep.n_samples[p] for p in phases if rep.n_samples[p] > 0))


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
    rms_gain: float = math.nan  # 1 - rms / reference rms (nan: not given)
    null_consistent: bool = False
    reason: str = ""  # why not found ("" when found)

    def fails_only_on_error(self, min_gain: float, min_rms_gain: float, need_rms: bool = True) -> bool:
        """Not found only because ``delta <= k_se * se``: the gain exceeds ``min_gain``, the RMS
        gain reaches ``min_rms_gain`` (a missing RMS gain passes only with ``need_rms=False``) and
        the fit is not at its null value. (The evidence test is applied first, so its ``reason``
        hides whether the others hold.)"""
        rms_ok = self.rms_gain >= min_rms_gain if math.isfinite(self.rms_gain) else not need_rms
        return (
            not self.found
            and self.reason.startswith("evidence")
            and math.isfinite(self.delta)
            and self.delta > min_gain
            and rms_ok
            and not self.null_consistent
        )


@dataclass
class RankReport:
    base_log_evidence: float
    base_log_evidence_se: float
    rows: list[CandidateRow]  # sorted by delta, largest first
    winner: str | None
    min_gain: float
    k_se: float
    notes: list[str] = field(default_factory=list)
    min_rms_gain: float = 0.30
    reference: str = "base"  # "base" or the null-consistent fit used as the reference
    #: ``(dlogZ, se)`` of the local comparison that named the winner (:func:`.amend.promote_local`), else None
    local: tuple | None = None

    @property
    def verdict(self) -> str:
        if self.winner is None:
            return NO_FINDING
        r = next(r for r in self.rows if r.name == self.winner)
        # a winner named on the local comparison says so: its global gain is within its error by construction
        gain = (
            f"dlogZ = {r.delta:.2f} +- {r.delta_se:.2f}"
            if self.local is None
            else f"named on the local comparison: dlogZ = {self.local[0]:.2f} +- {self.local[1]:.2f} against the base "
            f"model refitted in its material mode, {r.delta:.2f} +- {r.delta_se:.2f} against the reference"
        )
        return (
            f"missing physics: {self.physics}"
            + (f" ({self.winner} model" if self.physics != self.winner else " (")
            + (", " if self.physics != self.winner else "")
            + gain
            + (f", residual RMS {100 * r.rms_gain:.0f} % lower" if math.isfinite(r.rms_gain) else "")
            + (
                f", removes {100 * r.residual_removed:.0f} % of the localised residual"
                if math.isfinite(r.residual_removed)
                else ""
            )
            + ")"
            + "".join(
                f"; not distinguishable from {name} (dlogZ {d:.0f} +- {se:.0f} below)" for name, d, se in self.rivals
            )
        )

    @property
    def rivals(self) -> list[tuple[str, float, float]]:
        """Other physics the evidence cannot tell from the winner: ``(physics, gap, se)`` for every
        found-eligible row of another family whose log-evidence is within ``k_se`` errors of the
        winner's (``gap`` = winner's minus its, ``se`` = both fits' errors in quadrature; the
        reference cancels), and every found-eligible row the winner's entry lists as
        ``confusable`` (zipper and the phase/amplitude asymmetry: both sums of delayed copies of
        one waveform, which a GAW alone cannot tell apart) whatever the gap. The winner is still
        the largest; a rival is reported, not scored."""
        if self.winner is None:
            return []
        from .extensions import CATALOGUE, physics_of

        w = next(r for r in self.rows if r.name == self.winner)
        out, seen = [], {self.physics}
        for r in self.rows:
            f = physics_of(r.name)
            if r.name == w.name or f in seen:
                continue
            qualifies = r.found or r.fails_only_on_error(self.min_gain, self.min_rms_gain, need_rms=False)
            gap, se = w.delta - r.delta, math.hypot(w.log_evidence_se, r.log_evidence_se)
            confusable = w.name in CATALOGUE and r.name in CATALOGUE[w.name].confusable
            if qualifies and math.isfinite(gap) and math.isfinite(se) and (gap <= self.k_se * se or confusable):
                out.append((f, float(gap), float(se)))
                seen.add(f)
        return out

    @property
    def physics(self) -> str | None:
        """The physics named: the winner's family (``Extension.physics``), or None."""
        from .extensions import physics_of

        return physics_of(self.winner)

    def table(self) -> list[dict]:
        return [r.__dict__.copy() for r in self.rows]


def rank_extensions(
    base,
    candidates: dict,
    *,
    residual: dict | None = None,
    n_extra: dict | None = None,
    rms: dict | None = None,
    base_rms: float | None = None,
    null: dict | None = None,
    references: dict | None = None,
    min_gain: float = 3.0,
    k_se: float = 3.0,
    min_rms_gain: float = 0.30,
) -> RankReport:
    """Rank candidate extended fits against ``base`` (module docstring: rule and reference).

    Parameters
    ----------
    base : Posterior-like (``log_evidence``, ``log_evidence_se``), ``(logZ, se)`` or dict.
    candidates : name -> same kinds as ``base`` (each an independent fit of the extended model).
    residual : name -> fraction of the localised residual removed (:func:`residual_removed`).
    n_extra : name -> number of extra parameters (reported only).
    rms, base_rms : name -> residual RMS of each fit, and the base fit's (mm^2). When given, the
        effect-size criterion applies (a candidate without a finite RMS is then never found).
    null : name -> whether the fit sits at its null value (:func:`null_consistent`).
    references : label -> ``(log Z, se, rms)`` of further *base-model* evidence estimates (lower
        bounds, e.g. a base fit re-run around an extended fit's material mode); the reference is
        the largest of the base, these and the null-consistent fits.
    """
    z0, s0 = _lz(base)
    null = dict(null or {})
    use_rms = rms is not None
    rms = dict(rms or {})
    ref, notes = "base", []
    r0 = float(base_rms) if base_rms is not None else math.nan
    for name, c in candidates.items():  # reference raised by null-consistent fits
        z, s = _lz(c)
        if null.get(name) and math.isfinite(z) and (not math.isfinite(z0) or z > z0):
            z0, s0, ref = z, s, name
            r0 = float(rms.get(name, math.nan)) if base_rms is not None else r0
    for label, (z, s, r) in (references or {}).items():
        if math.isfinite(z) and (not math.isfinite(z0) or z > z0):
            z0, s0, ref = float(z), float(s), label
            r0 = float(r) if base_rms is not None else r0
    if ref != "base" and ref not in candidates:
        notes.append(
            f"{ref}: a base-model fit with a higher log-evidence than the base fit (the base SMC missed "
            f"a material mode); gains are measured against it"
        )
    elif ref != "base":
        notes.append(
            f"{ref}: the fit sits at its null value (the base model) with a higher log-evidence than "
            f"the base fit, so the base SMC missed a material mode; gains are measured against {ref}"
        )
    rows = []
    for name, c in candidates.items():
        z, s = _lz(c)
        d = z - z0
        se = math.sqrt((s0 if math.isfinite(s0) else math.inf) ** 2 + (s if math.isfinite(s) else math.inf) ** 2)
        if not math.isfinite(se):
            notes.append(f"{name}: no Monte Carlo error for the log-evidence; cannot be declared found")
        g = (1.0 - float(rms[name]) / r0) if (name in rms and math.isfinite(r0) and r0 > 0) else math.nan
        is_null = bool(null.get(name, False))
        if not (math.isfinite(d) and math.isfinite(se) and d > min_gain and d > k_se * se):
            reason = f"evidence: dlogZ {d:.1f} +- {se:.1f} not > {min_gain:g} and > {k_se:g} se"
        elif use_rms and not (math.isfinite(g) and g >= min_rms_gain):
            reason = f"effect size: residual RMS {100 * g:.0f} % lower, below {100 * min_rms_gain:.0f} %"
        elif is_null:
            reason = "null value: extension parameters at their null value (a mode-finding gain)"
        else:
            reason = ""
        rows.append(
            CandidateRow(
                name,
                z,
                s,
                d,
                se,
                None if n_extra is None else n_extra.get(name),
                float((residual or {}).get(name, math.nan)),
                reason == "",
                g,
                is_null,
                reason,
            )
        )
    rows.sort(key=lambda r: -r.delta if math.isfinite(r.delta) else math.inf)
    winner = next((r.name for r in rows if r.found), None)
    return RankReport(z0, s0, rows, winner, min_gain, k_se, notes, min_rms_gain, ref)


def rank_best_of_base(
    base, candidates: dict, *, base_runs, mode_checks: dict | None = None, base_rms: float | None = None, **kw
) -> RankReport:
    """The naming rule of :func:`rank_extensions` against *every* base-model fit, with delta-method
    errors only: the rule for an irregular base fit on which nothing was named (:ref:`diagnose`
    section 3, "Best of all base fits").

    When the base runs land far apart (between-run error ``tau`` of hundreds of nats) the shipped
    rule adds ``tau`` in quadrature to every fit's error, and on an irregular likelihood that error
    swamps gains of a thousand nats and more. Here instead each extension is compared with the best
    of all base-model fits the diagnosis made -- every base run (``base_runs``: ``(log Z, se)``
    pairs), every mode check's evidence bound (``mode_checks``: label -> ``(log Z, se, rms)``) and
    every null-consistent refit (as in :func:`rank_extensions`) -- each carrying only its own
    reported error. The scatter of the base runs is then not an error of the comparison but a
    search over base-model modes, of which the best is kept. An SMC evidence estimate is unbiased
    for Z and non-negative, so by Markov's inequality an estimate lands ``d`` nats above the
    truth with probability at most ``exp(-d)``: an extension far above every base fit is not a
    lucky draw of its own sampler; what remains is the chance that all base fits missed a better
    base mode, which the mode check (the base refitted around the extension's own material mode)
    covers. The effect-size test (RMS gain against the reference fit) is unchanged.

    ``base``, ``candidates``, ``kw`` (``residual``, ``n_extra``, ``rms``, ``null``, ``min_gain``,
    ``k_se``, ``min_rms_gain``): as :func:`rank_extensions`, errors *without* ``tau``."""
    refs = {}
    for i, (z, s) in enumerate(base_runs or ()):
        refs[f"base run ({i})"] = (float(z), float(s), float(base_rms) if base_rms is not None else math.nan)
    for label, (z, s, r) in (mode_checks or {}).items():
        refs[f"base near {label}"] = (float(z), float(s), float(r))
    rep = rank_extensions(base, candidates, base_rms=base_rms, references=refs, **kw)
    rep.notes.append(
        f"irregular base fit, nothing named with the between-run error: every extension compared "
        f"with the best of {len(refs) + 1} base-model fits by their own errors (reference: "
        f"{rep.reference})"
    )
    return rep


def compare_fits(
    base_post,
    ext_posts: dict,
    *,
    min_gain: float = 3.0,
    k_se: float = 3.0,
    min_rms_gain: float = 0.30,
    null_sd: float = 2.0,
) -> RankReport:
    """:func:`rank_extensions` from fitted posteriors carrying predictions: the localised residual
    fraction and the residual RMS are computed on each posterior's predictive ensemble; the null
    check uses ``post.info["extension"]`` (set by :func:`.fit.fit_extended`) or the dict key."""
    from .locate import locate

    def rep(p):
        g = p.recorded_gaws()
        return locate(np.asarray(p.obs_gaw, dtype=float)[: g.shape[1]], g, p.fps)

    def rms_of(p):
        g = p.recorded_gaws()
        y = np.asarray(p.obs_gaw, dtype=float)[: g.shape[1]]
        return float(np.sqrt(np.mean((y - g.mean(axis=0)) ** 2)))

    r0 = rep(base_post)
    res = {n: residual_removed(r0, rep(p)) for n, p in ext_posts.items()}
    from .extensions import get
    from .fit import null_drops, param_table

    nx = {n: len(get(p.info.get("extension", n)).params) for n, p in ext_posts.items()}
    nul = {
        n: null_consistent(*param_table(p), p.info.get("extension", n), null_sd, drops=null_drops(p))
        for n, p in ext_posts.items()
    }
    return rank_extensions(
        base_post,
        ext_posts,
        residual=res,
        n_extra=nx,
        rms={n: rms_of(p) for n, p in ext_posts.items()},
        base_rms=rms_of(base_post),
        null=nul,
        min_gain=min_gain,
        k_se=k_se,
        min_rms_gain=min_rms_gain,
    )
