"""Stop 25 lead: can an extension reach its floor at all? (a few simulations, development data)

A "refit short of its floor" (seed 6 11, seed 7 06 and 21) is either a sampler that missed the
extension's mode or an extension that cannot reproduce the generator's richer mechanism. This
evaluates the extension at the case's *true* material parameters over a grid of its own
parameters (the generator's truth is read: development use only, never in the fitting code) and
prints the best log-likelihood and residual RMS next to the base model's at the same point and
the refit's. Usage:
    .venv/bin/python benchmarks/results/leads/oracle_floor.py SUITE_DIR REPORT_JSON CASE EXT PARAM=lo:hi:n [...]
"""
import itertools
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))


def main(argv):
    suite, report, cid, ext = Path(argv[0]), Path(argv[1]), argv[2], argv[3]
    grids = {}
    for a in argv[4:]:
        name, spec = a.split("=")
        lo, hi, n = spec.split(":")
        grids[name] = np.linspace(float(lo), float(hi), int(n))
    from benchmarks.bench_diagnose import _problem
    from vfcore.diagnose.fit import ExtendedEvaluator
    meta = json.loads((suite / "cases.json").read_text())
    case = next(c for c in meta["cases"] if c["id"] == cid)
    truth = json.loads((suite / "truth.json").read_text())["cases"][cid]
    pb = _problem(meta, case, suite, None, 1.0)          # bench_diagnose defaults (--sigma-e 1, --noise fixed)
    ev = ExtendedEvaluator(pb, ext, integrate=False)
    base_names = [n for n in ev.prior.names if n not in grids]
    theta0 = [truth["truth"][n] for n in base_names]
    combos = list(itertools.product(*grids.values()))
    rows = np.array([theta0 + list(c) for c in combos])
    e = ev(rows)
    y = np.asarray(pb.obs_compared, dtype=float)
    rep = json.loads(report.read_text())
    ref_rms = min([rep["base"]["residual_rms"]] + [v["residual_rms"] for v in rep["refits"].values()
                                                    if v.get("null_consistent")])
    sigma = truth["sigma_mm2"]
    out = []
    for c, ll, g in zip(combos, e.loglik, e.gaw):
        rms = float(np.sqrt(np.nanmean((y[: len(g)] - g) ** 2)))
        out.append((ll, rms, c))
    out.sort(key=lambda t: -t[0])
    print(f"case {cid} ({truth['label']}; {json.dumps(truth['effect'])})")
    print(f"  sigma {sigma:.3f}; reference fit RMS {ref_rms:.3f} (floor {100 * (1 - sigma / ref_rms):.0f} %); "
          f"{ext} refit RMS {rep['refits'].get(ext, {}).get('residual_rms', float('nan')):.3f}")
    for ll, rms, c in out[:5]:
        print(f"  truth materials, {dict(zip(grids, np.round(c, 4)))}: loglik {ll:.1f}, RMS {rms:.3f} "
              f"({100 * (1 - rms / ref_rms):.0f} % below the reference fit)")


if __name__ == "__main__":
    main(sys.argv[1:])
