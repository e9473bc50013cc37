"""A recording checked against a reach ensemble: per-measure verdicts, the joint "near" count, the message.

The rules (inside the 5-95 % range, marginal up to the extreme draws, outside beyond them; the hard measures;
the unknown area scale) are stated in :mod:`.reach`'s docstring.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from .reach_ensemble import MEASURES, ReachEnsemble

#: Measures whose being outside makes the verdict "outside"; the quotients make it at most "marginal".
HARD_MEASURES = ("f0_hz", "max_area_mm2")
#: A draw is "near" the recording when its f0 is within this relative distance ...
NEAR_F0 = 0.10
#: ... and its peak area within this factor of the recording's.
NEAR_AREA = 1.5


@dataclass
class ReachVerdict:
    """The outcome of :func:`check_reach`. ``verdict``: "inside", "marginal", "outside" or "unchecked"."""

    verdict: str
    message: str
    measures: dict = field(default_factory=dict)  # column -> {value, q05, q50, q95, min, max, verdict}
    n_draws: int = 0
    phonating_fraction: float = math.nan
    n_near: int | None = None
    exact: bool = True
    key: str = ""
    hints: list[str] = field(default_factory=list)

    @property
    def outside(self) -> bool:
        return self.verdict == "outside"

    def warning(self, forced_by: str) -> str | None:
        """What a fit that goes ahead says about this verdict: the message of a marginal or unchecked
        recording, and of one outside the reach fitted anyway because of ``forced_by`` (the option that
        allowed it); ``None`` inside the reach."""
        if self.verdict == "outside":
            return f"{self.message} ({forced_by}: fitting anyway; expect a posterior piled on the prior's bounds)"
        if self.verdict in ("marginal", "unchecked"):
            return self.message
        return None

    def to_dict(self) -> dict:
        def clean(x):
            if isinstance(x, dict):
                return {k: clean(v) for k, v in x.items()}
            if isinstance(x, list):
                return [clean(v) for v in x]
            if isinstance(x, float):
                return x if math.isfinite(x) else None
            return x

        return clean(
            {
                "verdict": self.verdict,
                "message": self.message,
                "measures": self.measures,
                "n_draws": self.n_draws,
                "phonating_fraction": self.phonating_fraction,
                "n_near": self.n_near,
                "exact": self.exact,
                "key": self.key,
                "hints": list(self.hints),
            }
        )


def recording_measures(gaw, fps: float) -> dict[str, float]:
    """The measures of ``MEASURES`` of a recorded GAW (mm^2 at ``fps``)."""
    from ..measures import gaw_measures

    m = gaw_measures(np.asarray(gaw, dtype=float), float(fps))
    return {col: float(m[col]) for col, *_ in MEASURES}


def _fmt(x: float, fmt: str) -> str:
    return "nan" if not math.isfinite(x) else format(x, fmt)


def _hints(outs: dict[str, str], prior: Mapping | None) -> list[str]:
    """What would help, from which hard measures are beyond the reach and on which side."""
    from .prior import TABLE2_BOUNDS

    soft = prior is not None and all(
        tuple(prior["bounds"].get(n, ())) == tuple(b) or n in prior.get("fixed", {}) for n, b in TABLE2_BOUNDS.items()
    )
    hints = []
    f0 = outs.get("f0_hz")
    if f0 == "high":
        hints.append(
            (
                "the Table 2 priors describe a soft synthetic (silicone-like) fold; for a human voice use "
                "--prior-set human (human tissue), or "
                if soft
                else ""
            )
            + "raise the stiffness and pressure bounds (--prior E_body=LO:HI --prior E_cover=LO:HI "
            "--prior E_lig=LO:HI --prior p_sub=LO:HI) or lower rho, and check the frame rate (--fps)"
        )
    elif f0 == "low":
        hints.append(
            "lower the stiffness bounds (--prior E_body=LO:HI --prior E_cover=LO:HI) and check the frame rate (--fps)"
        )
    area = outs.get("max_area_mm2")
    if area in ("high", "low"):
        hints.append(
            "check the area calibration (px/mm of the video: areas scale with its square), or fit an "
            "unknown one (--uncalibrated, --area-scale LO:HI)"
            + (
                "; a larger p_sub or smaller x0 opens the model wider"
                if area == "high"
                else "; a smaller p_sub or larger x0 opens it less"
            )
        )
    if hints:
        hints.append(
            "a different mesh (--mesh) changes the fold's stiffness too; `vfinfer reach` builds the "
            "ensemble of a new prior to check it first"
        )
    return hints


def _measure_verdict(x: float, x_lo: float, x_hi: float, s: Mapping) -> str:
    """Verdict of one measure: the recorded value ``x`` standing for true values in ``[x_lo, x_hi]``, against
    the ensemble's statistics ``s`` of that measure."""
    if not math.isfinite(x):
        return "unknown"
    if s["n"] == 0:
        return "outside"
    if x_hi < s["min"] or x_lo > s["max"]:
        return "outside"
    if x_hi < s["q05"] or x_lo > s["q95"]:
        return "marginal"
    return "inside"


def _measure_text(
    x: float,
    x_lo: float,
    x_hi: float,
    s: Mapping,
    label: str,
    unit: str,
    fmt: str,
    area_scale: tuple[float, float] | None,
) -> str:
    """One measure's sentence of the message: the recorded value and what the model and prior reach."""
    u = f" {unit}" if unit else ""
    if s["n"] == 0:
        return f"recording {label} {_fmt(x, fmt)}{u}; no prior draw of this model phonates"
    side = "most" if x > s["q50"] else "least"
    bound = s["max"] if x > s["q50"] else s["min"]
    text = (
        f"recording {label} {_fmt(x, fmt)}{u}; this model and prior reach {_fmt(s['q05'], fmt)}-"
        f"{_fmt(s['q95'], fmt)}{u} (5-95 %), at {side} {_fmt(bound, fmt)}{u}"
    )
    if area_scale and not x_lo == x_hi:  # an interval of true values (a NaN measure has none)
        text = text.replace(
            f"{u};",
            f"{u} (a true {_fmt(x_lo, fmt)}-{_fmt(x_hi, fmt)}{u} for an area scale "
            f"in [{area_scale[0]:g}, {area_scale[1]:g}]);",
            1,
        )
    return text


def _n_near(rec: Mapping[str, float], ensemble: ReachEnsemble, area_scale: tuple[float, float] | None) -> int | None:
    """Phonating draws near the recording in f0 and peak area together; None without a usable f0 and area."""
    f0, area = float(rec.get("f0_hz", math.nan)), float(rec.get("max_area_mm2", math.nan))
    if not (math.isfinite(f0) and math.isfinite(area) and area > 0):
        return None
    mf, ma = ensemble.measures["f0_hz"], ensemble.measures["max_area_mm2"]
    with np.errstate(invalid="ignore", divide="ignore"):
        a_lo, a_hi = (area / area_scale[1], area / area_scale[0]) if area_scale else (area, area)
        near = (
            ensemble.phonates & (np.abs(mf - f0) <= NEAR_F0 * f0) & (ma >= a_lo / NEAR_AREA) & (ma <= a_hi * NEAR_AREA)
        )
    return int(np.count_nonzero(near))


def _message(
    verdict: str, parts_out: list[str], parts_marg: list[str], n_near: int | None, where: str, rec: Mapping[str, float]
) -> str:
    """The verdict's sentence, before the hints."""
    if verdict == "outside":
        return (
            "recording outside this model's reach: "
            + "; ".join(parts_out)
            + f" ({where})"
            + ("; also " + "; ".join(parts_marg) if parts_marg else "")
        )
    if verdict == "marginal":
        bits = parts_out + parts_marg
        if n_near == 0:
            bits.append(
                f"no phonating draw has f0 within {NEAR_F0:.0%} and peak area within a factor "
                f"{NEAR_AREA:g} of the recording's together"
            )
        return "recording at the margin of this model's reach: " + "; ".join(bits) + f" ({where})"
    f0, area = float(rec.get("f0_hz", math.nan)), float(rec.get("max_area_mm2", math.nan))
    return (
        f"recording inside this model's reach: f0 {_fmt(f0, '.0f')} Hz, peak area {_fmt(area, '.3g')} mm^2 "
        f"({n_near} draws near it; {where})"
    )


def check_reach(
    rec: Mapping[str, float],
    ensemble: ReachEnsemble | None,
    *,
    exact: bool = True,
    area_scale: tuple[float, float] | None = None,
) -> ReachVerdict:
    """Compare a recording's measures ``rec`` (:func:`recording_measures`) with ``ensemble``.

    ``exact`` False: the ensemble is of a wider prior (:func:`find_ensemble`); then only "outside" is a
    verdict, anything else is "unchecked". ``ensemble`` None: "unchecked". ``area_scale`` ``(k_lo, k_hi)``:
    the recorded areas are ``k`` times the true ones with ``k`` unknown in that box; the peak area is then
    checked as the interval of true areas it may stand for."""
    if ensemble is None:
        return ReachVerdict(
            "unchecked",
            "the model's reach was not checked: no reach ensemble matches this configuration and prior",
            exact=False,
        )
    st = ensemble.stats()
    n, frac = ensemble.n, ensemble.phonating_fraction
    per: dict[str, dict] = {}
    outs: dict[str, str] = {}
    parts_out, parts_marg = [], []
    for col, label, unit, fmt in MEASURES:
        x = float(rec.get(col, math.nan))
        s = st[col]
        # the true values the recorded one may stand for: one point, or an interval under an unknown area scale
        x_lo, x_hi = (x / area_scale[1], x / area_scale[0]) if (area_scale and col == "max_area_mm2") else (x, x)
        v = _measure_verdict(x, x_lo, x_hi, s)
        per[col] = {"value": x, **{k: s[k] for k in ("q05", "q50", "q95", "min", "max")}, "verdict": v, "unit": unit}
        text = _measure_text(x, x_lo, x_hi, s, label, unit, fmt, area_scale)
        if v == "outside":
            outs[col] = "high" if (s["n"] and x_lo > s["max"]) else "low"
            parts_out.append(text)
        elif v == "marginal":
            parts_marg.append(text)
    n_near = _n_near(rec, ensemble, area_scale)
    if any(c in outs for c in HARD_MEASURES):
        verdict = "outside"
    elif outs or parts_marg or n_near == 0:
        verdict = "marginal"
    else:
        verdict = "inside"
    hints = _hints(outs, ensemble.prior) if verdict != "inside" else []
    where = f"{int(round(frac * n))} of {n} prior draws phonate" + (
        "" if exact else "; ensemble of a wider prior, which contains this one"
    )
    msg = _message(verdict, parts_out, parts_marg, n_near, where, rec)
    if hints:
        msg += "; what would help: " + "; ".join(hints)
    if not exact and verdict != "outside":
        return ReachVerdict(
            "unchecked",
            "the model's reach was not checked exactly: no reach ensemble of this "
            "prior; the recording is within the reach of a wider prior's ensemble for this "
            "configuration",
            per,
            n,
            frac,
            n_near,
            False,
            ensemble.key,
            [],
        )
    return ReachVerdict(verdict, msg, per, n, frac, n_near, exact, ensemble.key, hints)


def format_table(ens: ReachEnsemble) -> str:
    """Markdown table of an ensemble's reach (:ref:`inference`, "The model's reach")."""
    st = ens.stats()
    lines = ["| measure | unit | 5 % | 50 % | 95 % | min | max |", "|---|---|---|---|---|---|---|"]
    for col, label, unit, fmt in MEASURES:
        s = st[col]
        lines.append(
            f"| {label} | {unit or '1'} | "
            + " | ".join(_fmt(s[k], fmt) for k in ("q05", "q50", "q95", "min", "max"))
            + " |"
        )
    lines.append(
        f"\n{int(ens.phonates.sum())} of {ens.n} draws phonate ({ens.phonating_fraction:.1%}); "
        f"{int(ens.ok.sum())} simulations succeeded."
    )
    return "\n".join(lines)
