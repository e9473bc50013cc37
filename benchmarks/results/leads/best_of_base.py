"""Stop 23: the "best of all base fits" lead, evaluated on kept development reports (no simulation).

The lead (docs/diagnose_history.md, stop 22): when the base fit is irregular and no entry is
named, name the entry whose log-evidence beats *every* base-model fit (all base runs, the mode
checks' bounds, null-consistent refits) by > 3 nats and > 3 delta-method errors, with >= 30 %
lower residual RMS and parameters off their null value, instead of adding the base runs' scatter
in quadrature. This prints, for every report of held-out seeds 4 and 5 (now development data), what
that rule would name where the shipped rule named nothing. Usage:
    python benchmarks/results/leads/best_of_base.py
"""
import glob
import json
import math
import re
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


def truth(seed: int) -> dict[str, str]:
    out = {}
    for line in (HERE / f"heldout_seed{seed}" / "score.txt").read_text().splitlines():
        m = re.match(r"^(\d\d)\s+(\w+)\s", line)
        if m:
            out[m.group(1)] = m.group(2)
    return out


def base_fits(rep: dict) -> list[tuple[float, float, str]]:
    """(log Z, delta-method se, label) of every base-model fit a report records."""
    fits = []
    for n in rep["notes"]:
        if n.startswith("base runs"):
            fits += [(float(z), float(s), "base run") for z, s in re.findall(r"(-?[\d.]+) \+- ([\d.]+)", n)]
    if not fits:
        fits.append((rep["base"]["log_evidence"], rep["base"]["log_evidence_se"], "base run"))
    for k, v in rep["base"].get("mode_checks", {}).items():
        fits.append((v["log_evidence_bound"], v["log_evidence_bound_se"], f"base near {k}"))
    for k, v in rep["refits"].items():
        if v.get("null_consistent"):
            fits.append((v["log_evidence"], v["log_evidence_se"], f"{k} at its null"))
    return fits


def lead(rep: dict, min_gain=3.0, k_se=3.0, min_rms_gain=0.30):
    zb, sb, lab = max(base_fits(rep))
    best = None
    for k, v in rep["refits"].items():
        d, se = v["log_evidence"] - zb, math.hypot(v["log_evidence_se"], sb)
        if (not v.get("null_consistent") and v["rms_improvement"] >= min_rms_gain and d > min_gain
                and d > k_se * se and (best is None or d > best[1])):
            best = (k, d, se, v["rms_improvement"], lab)
    return best


def main():
    changed = 0
    for seed in (4, 5):
        tr = truth(seed)
        for f in sorted(glob.glob(str(HERE / f"heldout_seed{seed}" / "case_*.json"))):
            cid = f[-7:-5]
            rep = json.loads(Path(f).read_text())
            if rep["winner"] is not None:
                continue
            reg = rep["base"].get("regularity", {})
            irr = {True: "irregular", False: "regular"}.get(reg.get("irregular"), "regularity not recorded")
            if reg.get("irregular") is False:
                print(f"seed {seed} case {cid} ({tr[cid]}, regular): the lead does not apply")
                continue
            got = lead(rep)        # irregular, or not recorded (seed 4: applied anyway; it changes none)
            if got is None:
                print(f"seed {seed} case {cid} ({tr[cid]}, {irr}): still none")
                continue
            changed += 1
            k, d, se, g, lab = got
            print(f"seed {seed} case {cid} ({tr[cid]}, {irr}): would name {k}, dlogZ {d:.0f} +- {se:.1f} over the "
                  f"best base-model fit ({lab}), RMS {100 * g:.0f} % lower, roughness "
                  f"{reg.get('max_change', math.nan):.0f}")
    print(f"cases the lead changes: {changed} (a control named is a false alarm)")


if __name__ == "__main__":
    main()
