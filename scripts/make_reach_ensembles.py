"""Build the reach ensembles shipped in ``vfcore/data`` (:ref:`inference`, "The model's reach").

Protocol: for each configuration below, ``--n`` draws (default 2000, seed ``reach.DEFAULT_SEED``) from a prior
set (``--prior-set``: "paper" = Table 2, "human"; all seven parameters free), simulated in lock-step blocks of 32 (``vfcore.batch.simulate_many``)
for the configuration's duration, the transient discarded, the GAW taken at 4000 frames/s, and measured with
``vfcore.measures.gaw_measures`` (``vfcore.inference.reach.draw_measures``). One process, one core
(``OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1``). The configurations are those of ``vfinfer infer``'s defaults
(coarse mesh, dt 5e-5 s, 0.55 s with 0.25 s discarded) and the same at dt 1e-4 s.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python scripts/make_reach_ensembles.py [--n 2000] [--prior-set human]

Prints each ensemble's table (markdown) and its wall time.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from vfcore.config import SimConfig
from vfcore.inference.prior import PRIOR_SETS, Prior
from vfcore.inference.reach import DEFAULT_N, DEFAULT_SEED, build_ensemble, ensemble_path, format_table

CONFIGS = {
    "coarse, dt 5e-5 s (vfinfer infer defaults)": SimConfig(mesh="coarse", dt=5e-5, duration=0.55, discard=0.25),
    "coarse, dt 1e-4 s": SimConfig(mesh="coarse", dt=1e-4, duration=0.55, discard=0.25),
}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=DEFAULT_N)
    ap.add_argument("--seed", type=int, default=DEFAULT_SEED)
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "vfcore" / "data")
    ap.add_argument("--only", default=None, help="substring of a configuration's label")
    ap.add_argument("--prior-set", default="paper", choices=sorted(PRIOR_SETS))
    a = ap.parse_args(argv)
    for label, cfg in CONFIGS.items():
        if a.only and a.only not in label:
            continue

        def progress(done, total, el):
            print(f"\r{label}: {done}/{total} draws, {el:.0f} s", end="", file=sys.stderr, flush=True)

        ens = build_ensemble(
            cfg,
            Prior.default(prior_set=a.prior_set),
            a.n,
            a.seed,
            progress=progress,
            on_error=lambda m: print(f"\nerror: {m}", file=sys.stderr),
        )
        print(file=sys.stderr)
        path = ens.save(ensemble_path(ens.key, a.out))
        print(f"### {a.prior_set} priors, {label}: {ens.n} draws, {ens.wall_s:.0f} s on one core -> {path.name}\n")
        print(format_table(ens) + "\n", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
