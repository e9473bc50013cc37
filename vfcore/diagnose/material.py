"""Wrong material parameters as an explanation of their own (docs/diagnose.md, "Material first").

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

__all__ = ["ANCHOR", "pinned", "freed_problem", "judge", "prior_set_of"]

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


def judge(pinned_fit: dict, free_fit: dict, *, min_gain: float = 3.0, k_se: float = 3.0,
          min_rms_gain: float = 0.30) -> dict:
    """Whether freeing the pinned parameters explains the mismatch, by the rule that names a
    catalogue entry (docs/diagnose.md section 3): a log-evidence gain above ``min_gain`` nats and
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
    return {"delta": float(d), "delta_se": float(se), "rms_gain": float(gain), "found": not reason,
            "reason": reason}
