"""Wrong material parameters as an explanation of their own (:ref:`diagnose-naming-material-first`).

The GAW determines five combinations of the six scaled parameters (E_body, E_cover, E_lig, p_sub,
rho, eta; :data:`vfcore.inference.identify.SCALED`): multiplying all six by one factor leaves the
waveform exactly unchanged, so one of them, or a measurement, anchors the scale and the other five
can be estimated. A base model that holds some of those five at Table 3 leaves a misfit whenever the
recording's tissue differs from the silicone of Table 3, and every catalogue entry then competes to
absorb it: on a recording with E_lig, rho and eta far from Table 3 and a concealed chink, the
pinned base left 10.2 mm^2 against a noise of 0.46, and the frame-rate entry was named with
dlogZ = 15,385. The diagnosis therefore frees every such combination before it screens the
catalogue, and reports the gain of freeing them as its own explanation, "the fixed parameters were
wrong", judged by the same rule as a catalogue entry (evidence, effect size; :func:`judge`).
"""

from __future__ import annotations

import dataclasses
import math

from ..inference.identify import SCALED
from ..inference.prior import PRIOR_SETS, Prior
from ..inference.problem import Problem
from ..params import TABLE3
from .summary import fit_summary

__all__ = ["ANCHOR", "pinned", "freed_problem", "judge", "prior_set_of", "material_first", "material_sentence"]

#: The scale anchor when the user gives none: the density, the best known of the six in tissue
#: (1,000-1,100 kg/m^3 against decades of range in the moduli).
ANCHOR = "rho"


def prior_set_of(prior: Prior) -> str:
    """The named prior set whose bounds the prior's estimated parameters carry ("paper" when none matches)."""
    for name, bounds in PRIOR_SETS.items():
        if all(tuple(bounds.get(n, ())) == tuple(b) for n, b in prior.bounds.items()):
            return name
    return "paper"


def pinned(problem: Problem) -> list[str]:
    """The scaled parameters a GAW determines that ``problem`` holds at their Table 3 values: not
    estimated, not measured, at exactly the Table 3 value (left out, or fixed to it, as the command
    line does with every parameter it is not told about), and not the anchor. The anchor is
    :data:`ANCHOR` unless the user fixed one of the six elsewhere than Table 3, or measured one:
    that one anchors the scale, and the density is then free to move too. To keep a parameter at
    Table 3 on purpose, run the diagnosis with ``free_material=False``."""
    prior = problem.prior
    told = set(problem.measurements) | {n for n, v in prior.fixed.items() if v != getattr(TABLE3, n)}
    anchored = any(n in told for n in SCALED)
    return [n for n in SCALED if n not in prior.bounds and n not in told and not (n == ANCHOR and not anchored)]


def freed_problem(problem: Problem, names) -> Problem:
    """``problem`` with ``names`` estimated too, uniform over the bounds of the problem's prior set."""
    prior = problem.prior
    box = PRIOR_SETS[prior_set_of(prior)]
    bounds = dict(prior.bounds)
    bounds.update({n: tuple(box[n]) for n in names})
    fixed = {n: v for n, v in prior.fixed.items() if n not in bounds}
    return dataclasses.replace(problem, prior=Prior(bounds, fixed))


def judge(
    pinned_fit: dict, free_fit: dict, *, min_gain: float = 3.0, k_se: float = 3.0, min_rms_gain: float = 0.30
) -> dict:
    """Whether freeing the pinned parameters explains the mismatch, by the rule that names a
    catalogue entry (:ref:`diagnose-naming`): a log-evidence gain above ``min_gain`` nats and
    ``k_se`` standard errors, and a residual RMS at least ``min_rms_gain`` lower. ``pinned_fit`` and
    ``free_fit``: fit summaries (``log_evidence``, ``log_evidence_se``, ``residual_rms``)."""
    d = free_fit["log_evidence"] - pinned_fit["log_evidence"]
    se = math.hypot(pinned_fit["log_evidence_se"], free_fit["log_evidence_se"])
    gain = 1.0 - free_fit["residual_rms"] / pinned_fit["residual_rms"]
    if not (math.isfinite(d) and math.isfinite(se)):
        reason = "no finite evidence"
    elif d <= min_gain or d <= k_se * se:
        reason = f"evidence: dlogZ {d:.1f} +- {se:.1f} not above max({min_gain:g}, {k_se:g} se)"
    elif gain < min_rms_gain:
        reason = f"effect size: residual RMS {100 * gain:.0f} % lower, below {100 * min_rms_gain:.0f} %"
    else:
        reason = ""
    return {"delta": float(d), "delta_se": float(se), "rms_gain": float(gain), "found": not reason, "reason": reason}


def material_first(problem: Problem, base, fit, *, rule: dict):
    """Free the material combinations the problem holds at Table 3 before anything else
    (:mod:`.material`). ``base``: a posterior of ``problem`` or of the problem with fewer estimated
    parameters (a pinned fit, e.g. an inference job's posterior), or None. ``fit(problem)`` runs a
    base fit and returns ``(posterior, tau, factor, n_simulations, notes, runs)`` (``runs``: the
    ``(log Z, se)`` of every run).

    Returns ``(problem, base, fitted, record)``: the problem and base fit the diagnosis goes on
    with, the base-fit tuple of that fit (every simulation made here counted in it; ``None`` when
    nothing was pinned and ``base`` is used as it is), and the report's ``material`` record
    (``None`` when nothing was pinned). The freed model nests the pinned one, so it is kept
    whenever its evidence is not lower; the record says whether freeing the parameters *explains*
    the mismatch by the naming rule (``rule``: ``min_gain``, ``k_se``, ``min_rms_gain``)."""
    names = problem.prior.names
    if base is not None and tuple(base.names) != tuple(names):
        extra = [n for n in names if n not in base.names]
        if set(base.names) - set(names) or not extra:
            raise ValueError(f"the base posterior estimates {list(base.names)}; the problem estimates {list(names)}")
        table = problem.prior.to_params(problem.prior.lo)  # Table 3 or fixed values elsewhere
        pinned_problem = dataclasses.replace(
            problem,
            prior=type(problem.prior)(
                {n: b for n, b in problem.prior.bounds.items() if n not in extra},
                {**problem.prior.fixed, **{n: float(getattr(table, n)) for n in extra}},
            ),
        )
        free_problem, freed = problem, extra
    else:
        freed = pinned(problem)
        if not freed:
            return problem, base, None, None
        pinned_problem, free_problem = problem, freed_problem(problem, freed)
    if base is None:
        pin = fit(pinned_problem)
    else:
        pin = (base, 0.0, 1, 0, [], [(float(base.log_evidence), float(base.log_evidence_se))])
    free = fit(free_problem)
    s_pin = fit_summary(pin[0], pinned_problem.obs_compared, pinned_problem.fps)
    s_free = fit_summary(free[0], free_problem.obs_compared, free_problem.fps)
    verdict = judge(s_pin, s_free, **rule)
    keep_free = not s_free["log_evidence"] < s_pin["log_evidence"]
    table = pinned_problem.prior.to_params(pinned_problem.prior.lo)
    keys = ("log_evidence", "log_evidence_se", "residual_rms", "params")
    record = {
        "freed": list(freed),
        "held_at": {n: float(getattr(table, n)) for n in freed},
        "anchor": ANCHOR,
        **verdict,
        "kept": "free" if keep_free else "pinned",
        "pinned": {k: s_pin[k] for k in keys},
        "free": {k: s_free[k] for k in keys},
    }
    kept, other, pb = (free, pin, free_problem) if keep_free else (pin, free, pinned_problem)
    return pb, kept[0], (kept[0], kept[1], kept[2], kept[3] + other[3], kept[4], kept[5]), record


def material_sentence(m: dict) -> str:
    """One sentence of the material record: what was freed and what it gained."""
    held = ", ".join(f"{n} (held at {v:g})" for n, v in m["held_at"].items())
    return (
        f"freeing {held} gives dlogZ = {m['delta']:.2f} +- {m['delta_se']:.2f}, residual RMS "
        f"{100 * m['rms_gain']:.0f} % lower"
    )
