"""What integrating an entry's waveform-level parameters out costs per simulation, with each quadrature
round's alignments in one batch or one at a time.

    python benchmarks/studies/bench_integrated.py --cases runs/full10 --id 19 [--entries leak,asymmetry,zipper] [--rows 12]

For each catalogue entry with integrated parameters (or ``--entries``): ``--rows`` draws from the entry's
prior around one case of a concealed-effect suite are simulated once (the refit stage's evaluator,
``ExtendedEvaluator(integrate=True)``), then their scoring (``ExtendedEvaluator._integrated``: the nested
quadrature over the integrated parameters, :ref:`diagnose-cost-integrated-parameters`) is timed
``--repeats`` times each way, interleaved:

- batched (the library): every point of a quadrature round is aligned in one call
  (:func:`vfcore.inference.scoring.aligned_logliks`);
- one at a time (the baseline): the same call replaced by a loop of :func:`aligned_loglik`.

Prints ms per simulation for the simulation and both scorings (the fastest repeat of each, so a busy
machine shows less), and checks that the two scorings give the same bytes (log-likelihoods, conditional
means and sds, predictions). One process, one core.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks.suite import case_problem, one_case  # noqa: E402


def main(argv=None) -> int:
    import numpy as np

    import vfcore.inference.scoring as scoring
    from vfcore.diagnose.extensions import get, implemented
    from vfcore.diagnose.fit import ExtendedEvaluator

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", required=True, help="a suite's folder (benchmarks/concealed/generate.py)")
    ap.add_argument("--id", required=True, help="the case's id, e.g. 19")
    ap.add_argument(
        "--entries", default="", help="comma-separated entries (default: every one with integrated parameters)"
    )
    ap.add_argument("--rows", type=int, default=12, help="simulations per entry")
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args(argv)
    cases_dir = Path(a.cases)
    try:
        meta, case = one_case(cases_dir, a.id)
    except ValueError as exc:
        ap.error(str(exc))
    pb = case_problem(meta, case, cases_dir, None, 1.0)
    names = [n.strip() for n in a.entries.split(",") if n.strip()] or [n for n in implemented() if get(n).integrable]
    batched = scoring.aligned_logliks

    def one_at_a_time(hrs, problem):
        out = [scoring.aligned_loglik(h, problem) for h in hrs]
        return np.array([o[0] for o in out]), np.stack([o[1] for o in out])

    print(f"case {a.id} of {cases_dir}: window {pb.window} (max lag, compared frames); {a.rows} simulations per entry")
    for name in names:
        ev = ExtendedEvaluator(pb, name, integrate=True)
        _, base, phis = ev._draws(ev.prior.sample(a.rows, np.random.default_rng(0)))
        pairs = bool(ev.integrated)
        ev._simulate(base[:2], phis[:2], pairs=pairs)  # compiled kernels
        t0 = time.perf_counter()
        res = ev._simulate(base, phis, pairs=pairs)
        t_sim = time.perf_counter() - t0
        best = {"batched": np.inf, "one at a time": np.inf}
        outs = {}
        for _ in range(a.repeats):
            for label, f in (("one at a time", one_at_a_time), ("batched", batched)):
                scoring.aligned_logliks = f
                try:
                    t0 = time.perf_counter()
                    outs[label] = ev._integrated(res, phis)
                    best[label] = min(best[label], time.perf_counter() - t0)
                finally:
                    scoring.aligned_logliks = batched
        x, y = outs["batched"], outs["one at a time"]
        same = all(np.array_equal(getattr(x, k), getattr(y, k), equal_nan=True) for k in ("loglik", "extra", "gaw"))
        print(
            f"{name:12s} simulate {1e3 * t_sim / a.rows:6.1f} ms, score one at a time "
            f"{1e3 * best['one at a time'] / a.rows:6.1f} ms, batched {1e3 * best['batched'] / a.rows:6.1f} ms "
            f"per simulation ({best['one at a time'] / best['batched']:.2f}x); {int(x.ok.sum())}/{a.rows} scored; "
            f"{'the same bytes' if same else 'DIFFERENT'}",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
