"""The refit stage of a diagnosis: every catalogue entry's SMC fit, one after another or run together.

    python benchmarks/studies/bench_refits.py --cases runs/full10 --id 19 --workers 2

Fits every implemented catalogue entry (or ``--entries``) to one case of a concealed-effect suite with the
refit stage's settings (``DiagnoseOptions``: ``refit_n`` particles, integrated waveform parameters, the
diagnosis's seeds), through a pool of ``--workers`` processes with every batch cut into one equal part per
worker, as ``bench_diagnose.py`` runs them: first one fit after another (``fit_extended``), then all together
(``fit_extended_many``). Prints the wall time and simulations of each way, and checks that every fit's
samples and log-evidence are the same bytes both ways. The case's problem is the suite's base problem
(``benchmarks.suite.case_problem``), without the diagnosis's material-first step.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks.suite import case_problem, one_case  # noqa: E402
from vfcore.inference.importance import BalancedMap  # noqa: E402


def main(argv=None) -> int:
    import multiprocessing as mp
    import warnings

    import numpy as np

    from vfcore.diagnose.extensions import implemented
    from vfcore.diagnose.fit import ExtendedEvaluator, fit_extended
    from vfcore.diagnose.options import DiagnoseOptions
    from vfcore.diagnose.together import fit_extended_many

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", required=True, help="a suite's folder (benchmarks/concealed/generate.py)")
    ap.add_argument("--id", required=True, help="the case's id, e.g. 19")
    ap.add_argument("--entries", default="", help="comma-separated catalogue entries (default: every implemented one)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    cases_dir = Path(a.cases)
    try:
        meta, case = one_case(cases_dir, a.id)
    except ValueError as exc:
        ap.error(str(exc))
    pb = case_problem(meta, case, cases_dir, None, 1.0)
    names = [n.strip() for n in a.entries.split(",") if n.strip()] or list(implemented())
    o = DiagnoseOptions()
    jobs = [(n, o.refit_n, a.seed + 101 * (i + 1)) for i, n in enumerate(names)]
    pool = mp.get_context("spawn").Pool(a.workers)
    try:
        mapper = BalancedMap(pool.imap, a.workers)
        rng = np.random.default_rng(0)
        for n in names:  # compile every kernel in every worker first
            ev = ExtendedEvaluator(pb, n, integrate=o.integrate)
            list(mapper(ev, [ev.prior.sample(2 * a.workers, rng)]))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t0 = time.perf_counter()
            alone = []
            for n, k, s in jobs:
                t1 = time.perf_counter()
                alone.append(
                    fit_extended(
                        pb, n, n_particles=k, seed=s, map=mapper, chunk_size=o.chunk_size, integrate=o.integrate
                    )
                )
                print(
                    f"  alone: {n:<13} {int(alone[-1].n_simulations):>6} simulations {time.perf_counter() - t1:7.1f} s",
                    flush=True,
                )
            t_alone = time.perf_counter() - t0
            t0 = time.perf_counter()
            ends: dict[int, float] = {}
            together = fit_extended_many(
                pb,
                jobs,
                map=mapper,
                chunk_size=o.chunk_size,
                integrate=o.integrate,
                on_done=lambda i, _: ends.setdefault(i, time.perf_counter() - t0),
            )
            t_together = time.perf_counter() - t0
    finally:
        pool.close()
        pool.join()
    same = all(
        x.samples.tobytes() == y.samples.tobytes() and float(x.log_evidence) == float(y.log_evidence)
        for x, y in zip(alone, together)
    )
    sims = sum(int(p.n_simulations) for p in alone)
    print(f"case {a.id}: {len(names)} entries, {o.refit_n} particles, {a.workers} workers, {sims} simulations")
    print(f"  one after another: {t_alone:8.1f} s ({1e3 * t_alone / sims:.1f} ms a simulation)")
    print(
        f"  together:          {t_together:8.1f} s ({1e3 * t_together / sims:.1f} ms a simulation); "
        f"the last fits ended at " + ", ".join(f"{names[i]} {ends[i]:.0f} s" for i in sorted(ends, key=ends.get)[-3:])
    )
    print(f"  speed-up {t_alone / t_together:.2f}x; every fit the same bytes both ways: {same}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
