"""Scoring of concealed-effect benchmark runs (``bench_diagnose.py --score``), one suite or several pooled.

A *suite* is a generator output directory (``cases.json``, ``truth.json``; benchmarks/concealed)
and the directory of diagnosis reports run on it (``case_XX.json``). :func:`load_suite` joins the
two into one record per reported case; :func:`summarise` counts over any list of records, so
several suites pool by concatenating their records.

Besides the benchmark's acceptance figures (effect cases named right, false alarms in controls, RMS and
log-evidence of every named effect, cost), the summary splits the detection rate by

- the truth's effect (per-effect recall),
- the effect's strength: the generator's unabsorbed RMS over the noise sd (the part of the effect
  the best base-model fit cannot absorb; ``WEAK_SD`` separates weak from strong),
- the base fit's regularity (``report["base"]["regularity"]``; a report without it counts as
  unknown),

each with its 95 % Wilson interval (``scipy.stats.binomtest``), and counts the rescue refits
(fired, kept, by method) from the reports' notes.

Two presence checks beside the generator's own:

- the **presence audit** (``audit.json`` of ``generate.py --audit``, written before or without
  any diagnosis): the rate over the effects still present under its stronger absorption search;
- the **reference floor** of a case, ``1 - sigma / rms_ref``: the largest residual-RMS gain any
  extension could reach against the diagnosis' own reference fit (no fit goes below the noise).
  Below 30 % the diagnosis' base model has absorbed the effect to within the noise,
  whatever the generator's search found; misses are split by it. It reads the diagnosis'
  reports, so it explains misses and is never used to decide which cases count;
- the **absorption certificate** (``absorption.json`` beside the reports, ``generate.py --certify``,
  after the diagnosis): the base model polished from each report's base posterior on the clean
  waveform. A point within the presence threshold proves the effect absorbable, so the secondary
  rate "present under the audit and not absorbed" leaves such cases out; a larger misfit proves
  nothing, so it never adds a case. A secondary count, after the fact: the protocol's rate is the
  audit's.

A suite whose reports were not kept is scored from the per-case table that ``--score`` printed
(a text file) and the regenerated suite: :func:`load_table`, used when ``--out`` names a file. Each row's truth
label must match the regenerated suite (another suite is refused); a row whose effect
log-likelihood no longer matches is scored as tabled, without the audit, and listed.

The reports are read only; the truth is opened here, after the diagnosis, never by the fitting
code.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = [
    "CaseRecord",
    "load_suite",
    "load_table",
    "reference_rms",
    "summarise",
    "wilson",
    "format_summary",
    "WEAK_SD",
]

#: effects of the generator that no catalogue entry models (benchmarks/concealed/generate.py)
OUTSIDE = ("tremor", "diplophonia", "gamma")

#: unabsorbed effect RMS (in noise sds) below which an effect counts as weak
WEAK_SD = 2.0
#: the generator's presence rule: an effect the base model absorbs to below this many sds is absent
PRESENCE_SD = 1.02

_RESCUE = re.compile(
    r"rescue: the (\w+) refit ended at log Z (\S+), below the base's (\S+); refitted (.*?): "
    r"log Z (?:>=|=) (\S+) \+- (\S+)"
)


@dataclass
class CaseRecord:
    """One diagnosed case joined with its truth."""

    suite: str
    case: str
    label: str  # the truth's effect, or "control"
    present: bool  # generator presence rule (False for controls)
    strength_sd: float  # unabsorbed effect RMS / noise sd (nan for controls)
    winner: str | None  # the named extension, None (no missing physics), or "rejected"
    physics: str | None  # the winner's catalogue entry (lr_stiffness -> asymmetry)
    ok: bool
    gain: float  # log-evidence gain of the winner (nan if none)
    rms_improvement: float  # of the winner (nan if none)
    n_simulations: int
    wall_s: float
    effect_loglik: float
    irregular: bool | None  # base fit's regularity, None when the report predates the check
    rivals: list = field(default_factory=list)
    reference: str = "base"
    rescues: list = field(default_factory=list)  # (extension, method, kept)
    audit_present: bool | None = None  # presence under audit.json, None without one
    floor_gain: float = math.nan  # 1 - sigma / RMS of the diagnosis' reference fit
    regenerated: bool = True  # load_table: the row's recording regenerated
    wall_by_stage: dict = field(default_factory=dict)  # report "cost" (absent from older reports): stage -> seconds
    no_fit: bool = False  # the verdict was "the model does not fit"
    material: bool = False  # the verdict said the fixed parameters were wrong
    base_absorbed: bool | None = None  # absorption.json: absorbed from the diagnosis's base fit

    @property
    def outside(self) -> bool:
        """The truth's effect lies outside the catalogue: the right answer names nothing."""
        return self.label in OUTSIDE


def _truth_table(cases_dir: Path) -> dict:
    truth = json.loads((cases_dir / "truth.json").read_text())
    truth = truth.get("cases", truth)
    if isinstance(truth, list):
        truth = {t["id"]: t for t in truth}
    return truth


def _suite_truth(cases_dir: Path) -> tuple[dict, dict]:
    """A suite's truth table and its audit's cases ({} without ``audit.json``); raises
    ``FileNotFoundError`` naming a missing ``truth.json``."""
    if not (cases_dir / "truth.json").exists():
        raise FileNotFoundError(f"no truth.json in {cases_dir}: not a concealed-effect suite")
    audit = json.loads((cases_dir / "audit.json").read_text())["cases"] if (cases_dir / "audit.json").exists() else {}
    return _truth_table(cases_dir), audit


def _rescues(notes) -> list:
    out = []
    for n in notes:
        m = _RESCUE.match(n)
        if m:
            method = "reference" if "reference" in m.group(4) else "box"
            out.append((m.group(1), method, "not higher" not in n))
    return out


def _rivals(d: dict) -> list:
    """Rival physics of a report: its stored ``rivals``, or rebuilt from the ranking rows of a report
    without them."""
    if "rivals" in d:
        return [r["physics"] for r in d["rivals"]]
    if not d.get("winner"):
        return []
    from vfcore.diagnose.rank import CandidateRow, RankReport

    rows = [CandidateRow(**r) for r in d["ranking"]]
    return [f for f, _, _ in RankReport(math.nan, math.nan, rows, d["winner"], 3.0, 3.0).rivals]


def reference_rms(d: dict) -> float:
    """Residual RMS (mm^2) of a report's reference fit: the base fit, a base fit near an entry's
    material mode (``"base near X"``, the mode check), or a null-consistent refit."""
    ref = d.get("reference", "base")
    base = d.get("base", {})
    if ref.startswith("base near "):
        mc = base.get("mode_checks", {}).get(ref[len("base near ") :])
        if mc is not None:
            return float(mc["residual_rms"])
    elif ref in d.get("refits", {}):
        return float(d["refits"][ref]["residual_rms"])
    return float(base.get("residual_rms", math.nan))


def load_suite(cases_dir, out_dir, *, suite: str | None = None) -> list[CaseRecord]:
    """Records of every case of ``cases_dir``'s truth that has a report in ``out_dir`` (cases not
    yet diagnosed are skipped). Raises ``FileNotFoundError`` naming a missing ``truth.json``."""
    from vfcore.diagnose.extensions import physics_of

    cases_dir, out_dir = Path(cases_dir), Path(out_dir)
    truth, audit = _suite_truth(cases_dir)
    cert_path = out_dir / "absorption.json"
    cert = json.loads(cert_path.read_text())["cases"] if cert_path.exists() else {}
    suite = suite or cases_dir.name
    recs = []
    for cid, t in sorted(truth.items()):
        p = out_dir / f"case_{cid}.json"
        if not p.exists():
            continue
        d = json.loads(p.read_text())
        label = t.get("label") or t.get("effect")
        control = label == "control"
        present = False if control else bool(t.get("present", True))
        strength = (
            float(t.get("unabsorbed_rms_mm2", math.nan)) / float(t.get("sigma_mm2", math.nan))
            if not control
            else math.nan
        )
        el = float(t.get("effect_loglik", math.nan))
        if "error" in d:
            recs.append(
                CaseRecord(
                    suite, cid, label, present, strength, "rejected", None, False, math.nan, math.nan, 0, 0.0, el, None
                )
            )
            continue
        win = d.get("winner")
        physics = (d.get("physics") or physics_of(win)) if win else None
        # a two-effect case is named right by either effect; nothing is right for effects outside the catalogue
        ok = (win is None) if control or label in OUTSIDE else (physics in label.split("+"))
        gain = next((r["delta"] for r in d["ranking"] if r["name"] == win), math.nan) if win else math.nan
        imp = d["refits"][win]["rms_improvement"] if win else math.nan
        reg = d.get("base", {}).get("regularity")
        aud = None if control or cid not in audit else bool(audit[cid]["present"])
        floor = 1.0 - float(t.get("sigma_mm2", math.nan)) / reference_rms(d)
        recs.append(
            CaseRecord(
                suite,
                cid,
                label,
                present,
                strength,
                win,
                physics,
                ok,
                float(gain),
                float(imp),
                int(d.get("n_simulations", 0)),
                float(d.get("wall_s", 0.0)),
                el,
                None if reg is None else bool(reg["irregular"]),
                _rivals(d),
                d.get("reference", "base"),
                _rescues(d.get("notes", [])),
                aud,
                floor,
                wall_by_stage={
                    k: float(v.get("wall_s") or 0.0) for k, v in ((d.get("cost") or {}).get("by_stage") or {}).items()
                },
                no_fit=bool(d.get("fit_check") and not d["fit_check"]["fits"]),
                material=bool((d.get("material") or {}).get("found")),
                base_absorbed=None if control or cid not in cert else bool(cert[cid]["absorbed"]),
            )
        )
    return recs


_ROW = re.compile(r"^(\d\d)\s+(\w+)\s+(\w+?)\s*([YN])\s+(\S+)\s+(\S+)%\s+(\d+)\s+(\d+)\s+(\S+)\s+(\S+)\s+(.*)$")


def load_table(cases_dir, table, *, suite: str | None = None, rtol: float = 1e-4) -> list[CaseRecord]:
    """Records of a suite scored from a kept ``--score`` table (``table``, a text file) instead of
    reports: named winner, ok, dlogZ, RMS improvement, simulations and wall time per case, the
    rivals and the reference; the base fit's regularity and the reference floor are unknown.

    The suite is regenerated by the current generator, over a forward model that may have changed
    in its last digits (or, for an extension's mechanism, more) since the table was made. A row
    whose effect log-likelihood matches ``truth.json`` to ``max(0.051, rtol * |ll|)`` nats is the
    same recording and takes the suite's ``audit.json``; a row that does not is kept as it was
    scored (presence and strength from the table, ``*`` marking not present) with no audit
    (``audit_present=None``, so the generator's rule stands) and ``regenerated=False``.
    Raises ``ValueError`` naming the first row whose truth label differs (another suite), or when
    no row matches."""
    from vfcore.diagnose.extensions import physics_of

    cases_dir = Path(cases_dir)
    truth, audit = _suite_truth(cases_dir)
    suite = suite or cases_dir.name
    recs = []
    for line in Path(table).read_text().splitlines():
        m = _ROW.match(line)
        if not m:
            continue
        cid, label, named, ok, dz, imp, sims, wall, ell, unabs, rest = m.groups()
        t = truth.get(cid)
        if t is None or t["label"] != label:
            raise ValueError(
                f"{table}: case {cid} ({label}) does not match {cases_dir}/truth.json "
                f"({None if t is None else t['label']}): not the suite the table was made from"
            )
        control = label == "control"
        same = abs(float(t["effect_loglik"]) - float(ell)) <= max(0.051, rtol * abs(float(ell)))
        win = None if named == "None" else named
        rivals = rest.split("; rivals: ")[1].split(", ") if "; rivals: " in rest else []
        if control:
            present, strength = False, math.nan
        elif same:
            present = bool(t.get("present", True))
            strength = float(t["unabsorbed_rms_mm2"]) / float(t["sigma_mm2"])
        else:
            present, strength = not unabs.endswith("*"), float(unabs.rstrip("*"))
        recs.append(
            CaseRecord(
                suite,
                cid,
                label,
                present,
                strength,
                win,
                physics_of(win) if win else None,
                ok == "Y",
                float(dz),
                float(imp) / 100.0,
                int(sims),
                float(wall),
                float(ell),
                None,
                [r.strip() for r in rivals],
                rest.split(";")[0].strip(),
                [],
                None if control or not same or cid not in audit else bool(audit[cid]["present"]),
                regenerated=same,
            )
        )
    if recs and not any(r.regenerated for r in recs if r.label != "control"):
        raise ValueError(
            f"{table}: no effect case's log-likelihood matches {cases_dir}/truth.json: the suite did not regenerate"
        )
    return recs


def wilson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion ``k / n`` (nan, nan for n = 0)."""
    if n == 0:
        return math.nan, math.nan
    from scipy.stats import binomtest

    ci = binomtest(int(k), int(n)).proportion_ci(confidence_level=level, method="wilson")
    return float(ci.low), float(ci.high)


def _count(k: int, n: int) -> dict:
    lo, hi = wilson(k, n)
    return {"named": k, "of": n, "rate": k / n if n else math.nan, "wilson95": [lo, hi]}


def _rate(recs) -> dict:
    return _count(sum(r.ok for r in recs), len(recs))


def summarise(recs: list[CaseRecord], *, weak_sd: float = WEAK_SD) -> dict:
    """Counts over ``recs`` (one suite or several pooled); see the module docstring."""
    outside = [r for r in recs if r.outside]
    eff = [r for r in recs if r.label != "control" and not r.outside]
    present = [r for r in eff if r.present]
    ctl = [r for r in recs if r.label == "control"]
    named = [r for r in recs if r.winner not in (None, "rejected")]
    by_label = {lab: _rate([r for r in present if r.label == lab]) for lab in sorted({r.label for r in present})}
    strength = {
        f"weak (< {weak_sd:g} sd)": _rate([r for r in present if r.strength_sd < weak_sd]),
        f"strong (>= {weak_sd:g} sd)": _rate([r for r in present if r.strength_sd >= weak_sd]),
    }
    regularity = {
        "regular": _rate([r for r in present if r.irregular is False]),
        "irregular": _rate([r for r in present if r.irregular is True]),
        "unknown": _rate([r for r in present if r.irregular is None]),
    }
    confusion: dict = {}
    for r in present:
        if not r.ok:
            key = f"{r.label} -> {r.physics or 'none'}"
            confusion[key] = confusion.get(key, 0) + 1
    resc = {}
    for r in recs:
        for _, method, kept in r.rescues:
            m = resc.setdefault(method, {"fired": 0, "kept": 0})
            m["fired"] += 1
            m["kept"] += int(kept)
    fa = sum(not r.ok for r in ctl)
    audited = [r for r in eff if r.audit_present is not None]
    # suites with an audit: its presence; the others keep the generator's
    audit_present = [r for r in eff if (r.present if r.audit_present is None else r.audit_present)]
    certified = [r for r in eff if r.base_absorbed is not None]
    suites = {r.suite for r in recs}
    # present under the audit (or the generator's rule) and not shown absorbable from the diagnosis's base fit
    not_absorbed = [r for r in audit_present if not r.base_absorbed]
    missed = [r for r in present if not r.ok]
    shortlist = [r for r in present if r.ok or (r.physics is not None and r.label in r.rivals)]
    return {
        "suites": sorted(suites),
        "cases": len(recs),
        "present": _rate(present),
        "all_effect_cases": _rate(eff),
        # the truth named, or listed among the winner's rivals (entries the evidence does not separate from it)
        "named_or_rival": _count(len(shortlist), len(present)),
        "false_alarms": {"count": fa, "of": len(ctl), "wilson95": list(wilson(fa, len(ctl)))},
        # present effects given another physics's name (a wrong name, not a miss)
        "wrong_names": _count(sum(r.physics is not None and not r.ok for r in present), len(present)),
        # "the model does not fit" verdicts, per class of case
        "no_fit": {
            "present": _count(sum(r.no_fit for r in present), len(present)),
            "outside": _count(sum(r.no_fit for r in outside), len(outside)),
            "controls": _count(sum(r.no_fit for r in ctl), len(ctl)),
        },
        # effects outside the catalogue: silent (no name) is right
        "outside_silent": _rate(outside),
        "material_verdicts": sum(r.material for r in recs),
        "named_rms_ge_30pct": [sum(r.rms_improvement >= 0.3 for r in named), len(named)],
        "named_positive_gain": [sum(r.gain > 0 for r in named), len(named)],
        "by_effect": by_label,
        "by_strength": strength,
        "by_base_regularity": regularity,
        "misses": dict(sorted(confusion.items(), key=lambda kv: (-kv[1], kv[0]))),
        "rescues": resc,
        "audited_cases": len(audited),
        "present_under_audit": _rate(audit_present),
        "certified_cases": len(certified),
        "absorbed_from_base": [
            r.case if len(suites) == 1 else f"{r.suite}/{r.case}" for r in audit_present if r.base_absorbed
        ],
        "present_not_absorbed": _rate(not_absorbed),
        # load_table rows whose recording the regenerated suite no longer reproduces: no audit
        "not_regenerated": [f"{r.suite}/{r.case}" for r in eff if not r.regenerated],
        # over the misses whose floor is known (a kept table has none)
        "misses_floor_below_30pct": [
            sum(r.floor_gain < 0.3 for r in missed),
            sum(math.isfinite(r.floor_gain) for r in missed),
        ],
        "simulations_per_case": float(np.mean([r.n_simulations for r in recs])) if recs else math.nan,
        "wall_s_per_case": float(np.mean([r.wall_s for r in recs])) if recs else math.nan,
        # mean seconds per case in each stage, over the reports that carry their cost
        "wall_by_stage": _wall_by_stage([r for r in recs if r.wall_by_stage]),
    }


def _wall_by_stage(recs) -> dict:
    stages = sorted({k for r in recs for k in r.wall_by_stage})
    out = {k: float(np.mean([r.wall_by_stage.get(k, 0.0) for r in recs])) for k in stages}
    return {"cases": len(recs), "mean_s": dict(sorted(out.items(), key=lambda kv: -kv[1]))}


def _fmt_rate(x: dict) -> str:
    if not x["of"]:
        return "0/0"
    lo, hi = x["wilson95"]
    return f"{x['named']}/{x['of']} ({100 * x['rate']:.0f} %, Wilson 95 % {100 * lo:.0f}-{100 * hi:.0f} %)"


def format_summary(s: dict) -> str:
    """The summary as printed by ``bench_diagnose.py --score``."""
    lines = [
        f"suites: {', '.join(s['suites'])}; {s['cases']} cases",
        f"effect present, named right: {_fmt_rate(s['present'])}",
        f"all effect cases named right: {_fmt_rate(s['all_effect_cases'])}",
        f"present effect named or among the winner's rivals: {_fmt_rate(s['named_or_rival'])}",
        f"false alarms in controls: {s['false_alarms']['count']}/{s['false_alarms']['of']}",
        *(
            [
                f"present effects given a wrong name: {_fmt_rate(s['wrong_names'])}",
                "'the model does not fit' verdicts: "
                + "; ".join(f"{k} {_fmt_rate(v)}" for k, v in s["no_fit"].items() if v["of"]),
                f"effects outside the catalogue left unnamed: {_fmt_rate(s['outside_silent'])}",
            ]
            if "wrong_names" in s
            else []
        ),
        f"named effects with RMS improvement >= 30 %: {s['named_rms_ge_30pct'][0]}/{s['named_rms_ge_30pct'][1]}; "
        f"with dlogZ > 0: {s['named_positive_gain'][0]}/{s['named_positive_gain'][1]}",
        "by effect (present cases): " + "; ".join(f"{k} {v['named']}/{v['of']}" for k, v in s["by_effect"].items()),
        "by strength: " + "; ".join(f"{k} {_fmt_rate(v)}" for k, v in s["by_strength"].items()),
        "by base regularity: "
        + "; ".join(f"{k} {_fmt_rate(v)}" for k, v in s["by_base_regularity"].items() if v["of"]),
        "misses (truth -> named): " + (", ".join(f"{k} x{v}" for k, v in s["misses"].items()) or "none"),
        f"misses whose reference fit leaves < 30 % RMS to gain (1 - sigma/rms_ref): "
        f"{s['misses_floor_below_30pct'][0]}/{s['misses_floor_below_30pct'][1]} with a known floor",
        *(
            [
                f"effect present under the presence audit ({s['audited_cases']} effect cases audited, "
                f"the rest by the generator's rule), named right: {_fmt_rate(s['present_under_audit'])}"
            ]
            if s["audited_cases"]
            else []
        ),
        *(
            [
                f"absorbed from the diagnosis' base fit ({s['certified_cases']} effect cases certified; "
                f"absorption.json): {', '.join(s['absorbed_from_base']) or 'none'}; present under the audit and "
                f"not absorbed, named right: {_fmt_rate(s['present_not_absorbed'])}"
            ]
            if s.get("certified_cases")
            else []
        ),
        *(
            [
                f"not regenerated (effect log-likelihood changed; scored as tabled, generator's rule, no audit): "
                f"{', '.join(s['not_regenerated'])}"
            ]
            if s.get("not_regenerated")
            else []
        ),
        "rescue refits: "
        + (", ".join(f"{m} fired {v['fired']} kept {v['kept']}" for m, v in s["rescues"].items()) or "none"),
        f"simulations per case: mean {s['simulations_per_case']:.0f}; wall per case: mean {s['wall_s_per_case']:.0f} s",
        *(
            [
                f"wall per case by stage ({s['wall_by_stage']['cases']} reports with their cost): "
                + ", ".join(f"{k} {v:.0f} s" for k, v in s["wall_by_stage"]["mean_s"].items())
            ]
            if s.get("wall_by_stage", {}).get("cases")
            else []
        ),
    ]
    return "\n".join(lines)
