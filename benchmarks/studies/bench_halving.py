"""Successive halving in the continuation search: the optimum it reaches and what it costs.

For each ``case:model`` pair (``model`` a catalogue entry or ``base``) of a concealed-effect suite,
runs :func:`vfcore.diagnose.search.continuation_search` twice from the same Sobol design: the
default search (every kept start polished on every window) and ``halving=True`` (after each window
but the last only the better half of the starts go on). Prints each one's whole-window
log-likelihood, its simulations and its wall time, and the log-likelihood each start reached
without halving, so a lost winner shows as a start that was behind early and ahead at the end.

Run it only on suites already scored (development data; :ref:`validation-diagnose`): a suite
that still measures the code must not inform a setting. The search reads the public recordings
and ``cases.json``, never the truth. The suite of seed 8 (regenerated with
``python -m benchmarks.concealed.generate --out runs/concealedS8 --seed 8 --material three``):

    python benchmarks/studies/bench_halving.py --cases runs/concealedS8 \
        --runs 00:frame_rate,06:leak,05:base [--seed 1] [--n-keep 4]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", required=True, help="suite folder with cases.json and the recordings")
    ap.add_argument("--runs", required=True, help="comma-separated case:model pairs (model: an entry or 'base')")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--n-keep", type=int, default=None, help="design starts kept (default: the search's)")
    ap.add_argument("--sigma-e", type=float, default=1.0)
    a = ap.parse_args(argv)

    from benchmarks.suite import case_problem
    from vfcore.diagnose import get
    from vfcore.diagnose.search import CONTINUATION, continuation_search

    cases_dir = Path(a.cases)
    meta = json.loads((cases_dir / "cases.json").read_text())
    by_id = {c["id"]: c for c in meta["cases"]}
    runs = []
    for item in a.runs.split(","):
        cid, _, model = item.strip().partition(":")
        if cid not in by_id:
            raise SystemExit(f"--runs: no case {cid!r} in {cases_dir / 'cases.json'}")
        if model != "base":
            get(model)  # raises naming the unknown entry
        runs.append((cid, None if model == "base" else model))
    extra = {} if a.n_keep is None else {"n_keep": a.n_keep}
    print(f"search settings: {dict(CONTINUATION, **extra)}; seed {a.seed}")
    print(f"{'case':<5}{'model':<13}{'halving':<9}{'log L':>11}{'sims':>7}{'wall s':>8}  log L of each start")
    for cid, ext in runs:
        pb = case_problem(meta, by_id[cid], cases_dir, None, a.sigma_e)
        for halving in (False, True):
            t0 = time.perf_counter()
            r = continuation_search(pb, ext, seed=a.seed, halving=halving, **extra)
            wall = time.perf_counter() - t0
            starts = ", ".join(f"{v:.1f}" for v in r.start_logliks) if not halving else ""
            print(
                f"{cid:<5}{ext or 'base':<13}{'on' if halving else 'off':<9}{r.loglik:11.1f}{r.n_simulations:7d}"
                f"{wall:8.0f}  {starts}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
