"""Does each catalogue entry contain the base model? For one case of a concealed-effect suite and its diagnosis
report, the base model's log-likelihood at the report's base posterior mean against each entry's at the same
material point with its own parameters at their null values (an entry whose prior holds no null: every
combination of its bounds, the best kept). An entry that contains the base (leak 0, scale 1, ...) gives the base's
log-likelihood; the rescue of a failed refit (:ref:`diagnose-pipeline`) assumes every entry comes close to it.
The last column moves each null 1 % of its box inwards: how far below the base the entry is just off its null.

    python benchmarks/studies/entry_nesting.py --cases runs/full10 --report runs/diagnose_full10/case_19.json --id 19

Reads only the public ``cases.json``, the recording and the report; prints one line per entry.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import sys
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402

from benchmarks.suite import case_problem  # noqa: E402
from vfcore.diagnose.extensions import CATALOGUE  # noqa: E402
from vfcore.diagnose.search import model_evaluator, model_prior  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", required=True, help="suite directory (cases.json and the recordings)")
    ap.add_argument("--report", required=True, help="the case's diagnosis report (bench_diagnose.py case_XX.json)")
    ap.add_argument("--id", required=True, help="case id")
    ap.add_argument("--sigma-e", type=float, default=1.0)
    a = ap.parse_args()
    cases_dir = Path(a.cases)
    meta = json.loads((cases_dir / "cases.json").read_text())
    case = {c["id"]: c for c in meta["cases"]}[a.id]
    pb = case_problem(meta, case, cases_dir, None, a.sigma_e)
    rep = json.loads(Path(a.report).read_text())
    mean = np.array([rep["base"]["params"][n]["mean"] for n in pb.prior.names])
    base = float(model_evaluator(pb, None)(mean[None]).loglik[0])
    print(
        f"case {a.id}: base at its posterior mean {', '.join(f'{n}={v:.4g}' for n, v in zip(pb.prior.names, mean))}: "
        f"log-likelihood {base:.1f}"
    )
    print(
        f"{'entry':<14} {'own parameters (null, or the best bound)':<48} {'log-lik':>10} {'below base':>11} "
        f"{'1 % inside':>11}"
    )
    for name, ext in CATALOGUE.items():
        prior = model_prior(pb, name, integrate=False)
        own = prior.names[len(pb.prior.names) :]
        by_name = {p.name: p for p in ext.params}
        choices = [[by_name[n].null] if by_name[n].null is not None else [by_name[n].lo, by_name[n].hi] for n in own]
        ev = model_evaluator(pb, name, integrate=False)
        rows = np.array([np.concatenate([mean, c]) for c in itertools.product(*choices)])
        ll = np.asarray(ev(rows).loglik, dtype=float)
        j = int(np.argmax(ll))
        where = ", ".join(f"{n}={v:g}" for n, v in zip(own, rows[j, len(mean) :]))
        # continuity: every parameter with a null moved 1 % of its box into the box (towards the far
        # bound); an entry the rescue can return through stays within a few nats of the base there
        near = rows[j].copy()
        for k, n in enumerate(own):
            p = by_name[n]
            if p.null is not None:
                near[len(mean) + k] = p.null + 0.01 * (
                    (p.hi - p.null) if p.hi - p.null >= p.null - p.lo else (p.lo - p.null)
                )
        ll_near = float(ev(near[None]).loglik[0])
        print(f"{name:<14} {where:<48} {ll[j]:10.1f} {base - ll[j]:11.1f} {base - ll_near:11.1f}", flush=True)


if __name__ == "__main__":
    main()
