"""Stop 25: re-decide kept reports with the shipped best-of-base rule (no simulation).

For every kept report of the given held-out seeds whose base fit is irregular and on which
nothing was named, apply :func:`vfcore.diagnose.pipeline.best_of_base_from_summaries` -- the
function the pipeline now names with -- to the numbers the report kept, and print what it names. It must agree
with ``best_of_base.py`` (the pre-registered reading of the lead), case by case. The pipeline
also re-fits the base model around a winner's material mode when the report has no such mode
check; offline that cannot be done, and such a case is printed as needing one.
    .venv/bin/python benchmarks/results/leads/redecide.py 4 5 6 7
"""
import glob
import json
import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(HERE.parents[1]))

from best_of_base import truth  # noqa: E402  (same folder)


def base_runs(rep: dict) -> list[tuple[float, float]]:
    if "base_runs" in rep["base"]:
        return [tuple(x) for x in rep["base"]["base_runs"]]
    runs = []
    for n in rep["notes"]:
        if n.startswith("base runs"):
            runs += [(float(z), float(s)) for z, s in re.findall(r"(-?[\d.]+) \+- ([\d.]+)", n)]
    return runs or [(rep["base"]["log_evidence"], rep["base"]["log_evidence_se"])]


def redecide(rep: dict):
    from vfcore.diagnose.pipeline import best_of_base_from_summaries
    return best_of_base_from_summaries({**rep["base"], "base_runs": base_runs(rep)}, rep["refits"])


def main(seeds):
    changed = right = wrong = alarms = 0
    for seed in seeds:
        tr = truth(seed)
        for f in sorted(glob.glob(str(HERE / f"heldout_seed{seed}" / "case_*.json"))):
            cid = f[-7:-5]
            rep = json.loads(Path(f).read_text())
            if rep["winner"] is not None or rep["base"].get("regularity", {}).get("irregular") is not True:
                continue
            r = redecide(rep)
            if r.winner is None:
                print(f"seed {seed} case {cid} ({tr[cid]}): still none (reference {r.reference})")
                continue
            checked = r.winner in rep["base"].get("mode_checks", {})
            changed += 1
            right += r.winner == tr[cid]
            alarms += tr[cid] == "control"
            wrong += r.winner != tr[cid] and tr[cid] != "control"
            w = next(x for x in r.rows if x.name == r.winner)
            print(f"seed {seed} case {cid} ({tr[cid]}): names {w.name}, dlogZ {w.delta:.0f} +- {w.delta_se:.1f} over "
                  f"{r.reference}, RMS {100 * w.rms_gain:.0f} % lower"
                  + ("" if checked else "; its mode not yet re-fitted with the base model (the pipeline would)"))
    print(f"changed {changed}: right {right}, wrong {wrong}, false alarms {alarms}")


if __name__ == "__main__":
    main(tuple(int(a) for a in sys.argv[1:]) or (4, 5, 6, 7))
