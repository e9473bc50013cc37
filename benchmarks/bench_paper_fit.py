"""The paper's own experiment as a user runs it: a twin at Table 3 (medium mesh, dt 5e-5 s, 0.55 s with 0.25 s
discarded, 400 frames, N(0, 1 mm²) noise from ``--seed``; ``vfcore.inference.make_twin``) written as a GAW file,
then fitted by the command line with six material parameters free and x0 fixed:

    vfinfer infer twin.csv --sampler smc --mesh medium --dt 5e-5 --fix x0=8.4 --particles 100 --workers 2 --seed 1

Prints the fit's wall time, its time simulating and reducing (the ``timings.json`` it writes), its simulations and
a checksum of its samples (two code versions that claim the same sampler must print the same one). Run it with
the machine to itself; ``--src`` times another checkout (its numba kernels are compiled by a short warm-up fit
first, so neither timing pays for compilation).

    python benchmarks/bench_paper_fit.py [--out runs/paper_fit] [--src PATH] [--workers 2]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIT = ["--sampler", "smc", "--mesh", "medium", "--dt", "5e-5", "--fix", "x0=8.4", "--seed", "1"]


def write_twin(path: Path, seed: int) -> None:
    import numpy as np

    from vfcore import TABLE3, SimConfig
    from vfcore.inference.prior import Prior
    from vfcore.inference.twin import make_twin
    from vfvideo.io import write_gaw_csv

    prior = Prior.default({"x0": TABLE3.x0})
    cfg = SimConfig(mesh="medium", dt=5e-5)
    twin = make_twin(prior, cfg, seed=seed, truth=[getattr(TABLE3, n) for n in prior.names])
    y = twin.problem.obs_gaw
    write_gaw_csv(path, np.arange(y.size) / cfg.fps, y, cfg.fps)


def infer(src: Path, gaw: Path, out: Path, particles: int, workers: int) -> float:
    env = {
        **os.environ,
        "PYTHONPATH": str(src),
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "NUMBA_NUM_THREADS": "1",
        "MPLBACKEND": "Agg",
    }
    argv = [
        sys.executable,
        "-c",
        "import sys; from service.cli import main; sys.argv[0] = 'vfinfer'; main()",
        "infer",
        str(gaw),
        *FIT,
        "--particles",
        str(particles),
        "--workers",
        str(workers),
        "--out",
        str(out),
    ]
    t0 = time.perf_counter()
    subprocess.run(argv, env=env, check=True, cwd=out.parent, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="runs/paper_fit", help="folder for the twin and the fit's products")
    ap.add_argument("--src", default=str(ROOT), help="checkout to time (default: this one)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1, help="the twin's noise seed")
    a = ap.parse_args()
    out = Path(a.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    gaw = out / "twin.csv"
    write_twin(gaw, a.seed)
    src = Path(a.src).resolve()
    if src != ROOT:
        infer(src, gaw, out / "warm_up", 10, a.workers)
    wall = infer(src, gaw, out / "fit", 100, a.workers)
    t = json.loads((out / "fit" / "timings.json").read_text())
    digest = hashlib.sha256((out / "fit" / "samples.csv").read_bytes()).hexdigest()[:16]
    print(
        f"source {src}\nwall {wall:.1f} s (simulating {t['simulate_s']:.1f} s, reducing {t['reduce_s']:.1f} s), "
        f"{t['n_simulations']} simulations on {a.workers} workers; samples.csv sha256 {digest}"
    )


if __name__ == "__main__":
    main()
