"""Rescue statistics over a directory of diagnosis reports (case_XX.json)."""
import json, math, re, sys, glob
sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[3]))
from vfcore.diagnose.extensions import CATALOGUE  # noqa
d = sys.argv[1]
kinds = {}
try:
    for e in CATALOGUE.values() if isinstance(CATALOGUE, dict) else CATALOGUE:
        kinds[e.name] = e.kind
except Exception as exc:
    print("catalogue:", exc)
pat = re.compile(r"rescue: the (\w+) refit ended at log Z (\S+), below the base's (\S+); refitted around the base's material mode: log Z >= (\S+) \+- (\S+)")
tot = {"forward": [0, 0, 0, 0], "observation": [0, 0, 0, 0]}  # refits, fired, kept, within3
sims_total = sims_rescue = 0
still_below = []
for f in sorted(glob.glob(f"{d}/case_*.json")):
    r = json.load(open(f))
    sims_total += r["n_simulations"]
    z0 = r["base"]["log_evidence"]; s0 = r["base"]["log_evidence_se"]
    fired = {}
    for n in r["notes"]:
        m = pat.match(n)
        if m:
            fired[m.group(1)] = (float(m.group(2)), float(m.group(4)), "not higher" not in n)
    for name, a in r["refits"].items():
        k = kinds.get(name, "?")
        t = tot.setdefault(k, [0, 0, 0, 0])
        t[0] += 1
        if name in fired:
            t[1] += 1
            if fired[name][2]:
                t[2] += 1
                sims_rescue += a["n_simulations"]
        z1 = a["log_evidence"]; s1 = a["log_evidence_se"]
        if z1 >= z0 - max(3, 3 * math.hypot(s0, s1)):
            t[3] += 1
        else:
            still_below.append(z0 - z1)
        if name in fired:
            print(f"{f[-7:-5]} {name:12s} {k:11s} first {fired[name][0]:10.1f} rescue {fired[name][1]:10.1f} base {z0:10.1f} kept {fired[name][2]}")
for k, t in tot.items():
    print(f"{k}: refits {t[0]} rescue fired {t[1]} kept {t[2]}; final within max(3,3se) of base or above {t[3]}")
import statistics
if still_below:
    print(f"still below: {len(still_below)} median {statistics.median(still_below):.1f} max {max(still_below):.1f}")
print(f"simulations total {sims_total}, kept rescues {sims_rescue} ({100*sims_rescue/max(sims_total,1):.1f} %)")
