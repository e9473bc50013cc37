"""Concealed-effect benchmark: run the diagnosis blind on every case, then score against the truth.

The cases come from ``benchmarks/concealed/generate.py`` (a separate generator with richer
mechanisms than the fitted extensions). This script reads only the PUBLIC ``cases.json`` and the
GAW files while fitting; ``truth.json`` is opened afterwards, for scoring only (``--score``).

    python -m benchmarks.concealed.generate --out runs/concealed --seed 0
    python benchmarks/bench_diagnose.py --cases runs/concealed --out runs/diagnose --workers 2
    python benchmarks/bench_diagnose.py --cases runs/concealed --out runs/diagnose --score

Defaults (:ref:`validation-diagnose`): the simulated window of the suite's public forward-model
settings (``cases.json`` "model": 0.55 s simulated with 0.25 s discarded, the paper's and
``SimConfig``'s default), 2 base SMC runs of 40 particles (larger evidence kept), every catalogue
entry refitted with 24 particles, a refit that ended far below the base rescued from the base's
material mode (every entry, without the between-run error in the trigger), the window-continuation
search, naming rule with min_rms_gain 0.30. The particle counts are ``vfcore.diagnose.DiagnoseOptions``'s,
the defaults of the library, the CLI and the service alike.

Per case it writes ``<out>/case_XX.json`` (the diagnosis report; existing reports are kept, so an
interrupted run resumes) and a figure ``case_XX.png``. ``--score`` prints the per-case table,
the detection rate over effect cases, false alarms over controls, residual-RMS improvements,
log-evidence gains, simulation counts and wall times.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
import warnings
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.suite import case_problem  # noqa: E402
from vfcore.inference.importance import BalancedMap  # noqa: E402


def _mapper(pool, workers: int, store: Path | None):
    """The case's map: the pool's (balanced) or the builtin, through a CachedMap when ``store``."""
    from vfcore.inference.memo import CachedMap

    inner = pool.imap if pool is not None else map
    if store is not None:
        inner = CachedMap(inner, store)
    return (BalancedMap(inner, workers) if pool is not None else inner), inner


def run(a) -> None:
    from vfcore.diagnose.figure import plot_diagnosis
    from vfcore.diagnose.pipeline import diagnose
    from vfcore.inference.memo import account

    cases_dir, out = Path(a.cases), Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    meta = json.loads((cases_dir / "cases.json").read_text())
    cases = meta["cases"][: a.max_cases] if a.max_cases else meta["cases"]
    if a.ids:
        by_id = {c["id"]: c for c in meta["cases"]}
        cases = [by_id[i.strip()] for i in a.ids.split(",") if i.strip()]
    import multiprocessing as mp

    pool = mp.get_context("spawn").Pool(a.workers) if a.workers > 1 else None
    try:
        for case in cases:
            path = out / f"case_{case['id']}.json"
            if path.exists():
                continue
            try:
                pb = case_problem(meta, case, cases_dir, a.duration, a.sigma_e, a.discard, a.noise, a.lag_search)
            except ValueError as exc:  # the recording is rejected before any simulation
                path.write_text(json.dumps({"error": str(exc), "winner": None, "verdict": "rejected input"}))
                print(f"case {case['id']}: rejected input: {exc}", flush=True)
                continue
            store = Path(a.resume_store) / f"case_{case['id']}" if a.resume_store else None
            mapper, inner = _mapper(pool, a.workers, store)
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                rep = diagnose(
                    pb,
                    n_particles=a.particles,
                    seed=a.seed,
                    map=mapper,
                    chunk_size=a.chunk,
                    max_refits=a.max_refits or None,
                    refit_particles=a.refit_particles,
                    base_runs=a.base_runs,
                    min_rms_gain=a.min_rms_gain,
                    escalate_tau=None if a.escalate_tau <= 0 else a.escalate_tau,
                    escalate_refits=a.escalate_refits,
                    refit_start=a.refit_start,
                    shared_mode=a.shared_mode,
                    continuation=a.continuation,
                    continuation_entries=a.continuation_entries or None,
                    continuation_options={"halving": bool(a.halving)},
                )
            d = rep.to_dict()
            d["wall_s"] = time.perf_counter() - t0
            d["runner"] = {
                "escalate_refits": a.escalate_refits,
                "refit_start": a.refit_start,
                "continuation": a.continuation,
                "continuation_entries": a.continuation_entries,
                "halving": a.halving,
                "shared_mode": a.shared_mode,
                "seed": a.seed,
                "noise": a.noise,
                "lag_search": a.lag_search,
            }
            if store is not None:  # a resumed case: its earlier attempts' wall time counted in
                account(d, inner)
            plot_diagnosis(rep, pb, out / f"case_{case['id']}.png")
            tmp = path.with_suffix(".json.tmp")
            tmp.write_text(json.dumps(d, indent=1, default=float))
            os.replace(tmp, path)  # the report appears whole, after its figure
            if store is not None:
                shutil.rmtree(store, ignore_errors=True)
            print(
                f"case {case['id']}: {rep.verdict}  sims={rep.n_simulations}  {d['wall_s']:.0f} s  refits "
                + ", ".join(
                    f"{r['name']} d={r['delta']:.0f} rms={100 * r['rms_gain']:.0f}%"
                    + ("" if r["found"] else f" [{r['reason'].split(':')[0]}]")
                    for r in d["ranking"]
                ),
                flush=True,
            )
            by = d.get("cost", {}).get("by_stage", {})
            if by:
                print(
                    f"case {case['id']}: time by stage "
                    + ", ".join(
                        f"{k} {v['wall_s']:.0f} s" for k, v in sorted(by.items(), key=lambda kv: -kv[1]["wall_s"])
                    ),
                    flush=True,
                )
    finally:
        if pool is not None:
            pool.close()
            pool.join()


def score(a) -> None:
    """Per-case table and summary (benchmarks/scoring.py) of one suite, or of several pooled:
    ``--cases`` and ``--out`` then take comma-separated lists of equal length. An ``--out`` that
    is a file is a kept ``--score`` table of a suite whose reports were not kept (scoring.load_table)."""
    from benchmarks.scoring import PRESENCE_SD, format_summary, load_suite, load_table, summarise

    cdirs, odirs = [c for c in a.cases.split(",") if c], [o for o in a.out.split(",") if o]
    if len(cdirs) != len(odirs):
        raise SystemExit(f"--score: {len(cdirs)} --cases directories but {len(odirs)} --out directories")
    suites = [(Path(c), (load_table if Path(o).is_file() else load_suite)(c, o)) for c, o in zip(cdirs, odirs)]
    recs = [r for _, rs in suites for r in rs]
    multi = len(suites) > 1
    print(
        f"{'case':<{14 if multi else 5}}{'truth':<12}{'named':<13}{'ok':<4}{'dlogZ':>9}{'RMS impr':>9}{'sims':>7}"
        f"{'wall s':>8}{'effect ll':>11}{'unabs/sd':>9}{'audit':>6}{'floor':>6}{'base':>5}  reference"
    )
    for r in recs:
        cid = f"{r.suite}/{r.case}" if multi else r.case
        ref = r.reference + ("; rivals: " + ", ".join(r.rivals) if r.rivals else "")
        reg = {None: "?", True: "irr", False: "reg"}[r.irregular]
        aud = {None: "", True: "pres", False: "abs"}[r.audit_present]
        print(
            f"{cid:<{14 if multi else 5}}{r.label:<12}{str(r.winner):<13}{'Y' if r.ok else 'N':<4}{r.gain:9.1f}"
            f"{100 * r.rms_improvement:8.0f}%{r.n_simulations:7d}{r.wall_s:8.0f}{r.effect_loglik:11.1f}"
            f"{r.strength_sd:9.2f}{'' if r.present or r.label == 'control' else '*'}{aud:>6}"
            f"{100 * r.floor_gain:5.0f}%{reg:>5}  {ref}"
        )
    if any(r.label != "control" and not r.present for r in recs):
        print(
            f"\n* effect not present (absorbed by the base model to < {PRESENCE_SD:.2f} sigma; generator presence "
            "rule): not counted in the present-effect rate"
        )
    print(
        "audit: presence under the suite's audit.json (generate.py --audit; pres / abs), blank without one; "
        "floor: 1 - sigma / RMS of the diagnosis' reference fit, the largest RMS gain any extension could reach"
    )
    print()
    print(format_summary(summarise(recs)))
    print("(wall per case as run: see --workers)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", required=True)
    ap.add_argument(
        "--out",
        required=True,
        help="reports directory; with --score, a kept --score table file is read instead of reports",
    )
    ap.add_argument("--score", action="store_true", help="score existing reports against truth.json")
    from vfcore.diagnose.options import DiagnoseOptions

    d = DiagnoseOptions()
    ap.add_argument("--particles", type=int, default=d.n_particles)
    ap.add_argument("--base-runs", type=int, default=2, help="independent base SMC runs, largest evidence kept")
    ap.add_argument(
        "--max-refits",
        type=int,
        default=0,
        help="observation-level refits, best screened first (0 = every one; forward-level: all)",
    )
    ap.add_argument("--refit-particles", type=int, default=d.refit_particles)
    ap.add_argument("--min-rms-gain", type=float, default=0.30)
    ap.add_argument(
        "--duration",
        type=float,
        default=None,
        help="simulated time, s (default: the suite's cases.json model setting, 0.55)",
    )
    ap.add_argument(
        "--discard",
        type=float,
        default=None,
        help="simulated transient discarded, s (default: the suite's setting, 0.25; some truths "
        "are not a settled limit cycle by 0.15 s, docs/diagnose.md section 4)",
    )
    ap.add_argument("--sigma-e", type=float, default=1.0)
    ap.add_argument(
        "--noise",
        choices=("fixed", "marginal"),
        default="fixed",
        help="noise model of the likelihood (docs/inference.md, 'Unknown noise level'); the suites' "
        "results so far were measured with 'fixed'",
    )
    ap.add_argument(
        "--escalate-tau",
        type=float,
        default=10.0,
        help="between-run error (nats) of the base runs above which the particles are doubled (0 = never)",
    )
    ap.add_argument(
        "--escalate-refits",
        action=argparse.BooleanOptionalAction,
        default=d.escalate_refits,
        help="an escalation also doubles the particles of every later fit (default: "
        "vfcore.diagnose.DiagnoseOptions().escalate_refits)",
    )
    from vfcore.diagnose.options import REFIT_STARTS

    ap.add_argument(
        "--refit-start",
        choices=REFIT_STARTS,
        default=d.refit_start,
        help="where the refits' SMC starts: the prior, or the base posterior (the rescue's "
        "reference-started SMC; default: vfcore.diagnose.DiagnoseOptions().refit_start)",
    )
    from vfcore.observe import LAG_SEARCHES

    ap.add_argument(
        "--lag-search",
        choices=LAG_SEARCHES,
        default="window",
        help="phase-alignment lag range (Problem.lag_search); 'periods': 1.5 periods only",
    )
    from vfcore.diagnose.search import CONTINUATION

    ap.add_argument(
        "--halving",
        action=argparse.BooleanOptionalAction,
        default=bool(CONTINUATION["halving"]),
        help="continuation search with successive halving of its starts (default: "
        "vfcore.diagnose.search.CONTINUATION; docs/diagnose.md section 4)",
    )
    ap.add_argument(
        "--continuation-entries",
        type=int,
        default=d.continuation_entries,
        help="refitted entries searched by continuation, largest refit evidence first (0: all; "
        "default: vfcore.diagnose.DiagnoseOptions().continuation_entries)",
    )
    ap.add_argument(
        "--continuation",
        action=argparse.BooleanOptionalAction,
        default=d.continuation,
        help="search the base and every entry by window continuation and fit from the optimum too "
        "(diagnose(continuation=...); default: vfcore.diagnose.DiagnoseOptions().continuation)",
    )
    ap.add_argument(
        "--shared-mode",
        action="store_true",
        help="refit every entry from the leading refit's material mode too (diagnose(shared_mode=True))",
    )
    ap.add_argument(
        "--resume-store",
        default="",
        help="directory of per-case stores of batch evaluations (vfcore.inference.memo.CachedMap): "
        "a case interrupted and run again reads its finished simulations back; a case's store "
        "is deleted once its report is written",
    )
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--chunk", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--max-cases", type=int, default=0)
    ap.add_argument("--ids", default="", help="comma-separated case ids, in the order to run them")
    a = ap.parse_args(argv)
    score(a) if a.score else run(a)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
