"""Where is the fold model's vibration irregular? The regularity check over the prior.

For ``--n`` scrambled-Sobol draws of the free parameters of the Table 2 prior (the concealed
suites' fixed values for the rest), in the suites' simulated window, each draw's waveform plus
noise (``--sigma`` mm^2, 500 frames at 2 kHz) is the recording, and
:func:`vfcore.diagnose.regularity.sensitivity` measures how much a relative 1e-6 change of the
parameters moves the log-likelihood (the *roughness*; > 1 nat = irregular), the second difference
at a relative 1e-4 and the waveform's aperiodicity (> 3 nats either = rough). Prints one line per
draw and the irregular and rough fractions per subglottal-pressure band (:ref:`diagnose-pipeline`,
"Regularity"; :ref:`validation-inference-roughness`). ``--six`` frees all six scaled parameters
of the paper's Table 2 box (x0 at Table 3), as the six-parameter calibrations do; ``--dt`` and
``--contact`` set the forward model.

    python benchmarks/bench_regularity.py --n 64 --seed 7
    python benchmarks/bench_regularity.py --n 64 --seed 7 --six --dt 5e-5 --contact layer
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from benchmarks.concealed.generate import BASE_CONFIG, public_fixed  # noqa: E402

FIXED = public_fixed()  # the concealed suites' fixed parameters
CFG = BASE_CONFIG  # and their forward model: coarse mesh, dt 1e-4, 0.55 s with 0.25 s discarded
BANDS = ((400.0, 800.0), (800.0, 1200.0), (1200.0, 1500.0), (1500.0, 1800.0))


def recording(theta, prior, cfg, *, sigma: float, seed: int, n: int = 500, fps: float = 2000.0):
    """The simulated GAW at ``theta`` sampled at ``fps`` (``n`` frames after 5 skipped) plus white
    noise of sd ``sigma`` (``seed``); ``None`` when the simulation fails."""
    from vfcore.forward import simulate
    from vfcore.result import HR_OVERSAMPLE

    r = simulate(prior.to_params(theta), cfg)
    if not r.ok:
        return None
    step = int(round(cfg.fps * HR_OVERSAMPLE / fps))
    y = np.asarray(r.gaw_hr[::step][5 : 5 + n], float)
    return y + sigma * np.random.default_rng(seed).standard_normal(y.size)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=64)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--sigma", type=float, default=0.5)
    ap.add_argument("--duration", type=float, default=0.55)
    ap.add_argument("--discard", type=float, default=0.25)
    ap.add_argument("--six", action="store_true", help="all six scaled parameters free (x0 at Table 3)")
    ap.add_argument("--dt", type=float, default=None, help="time step, s (default: the suites')")
    ap.add_argument("--contact", default=None, help="contact law (default: the suites')")
    a = ap.parse_args(argv)
    import dataclasses as dc

    from scipy.stats import qmc

    from vfcore.diagnose.regularity import sensitivity
    from vfcore.inference import Prior
    from vfcore.inference.problem import Problem
    from vfcore.params import TABLE3

    prior = Prior.default(fixed={"x0": TABLE3.x0} if a.six else FIXED)
    model = {k: v for k, v in (("dt", a.dt), ("contact", a.contact)) if v is not None}
    cfg = dc.replace(CFG, duration=a.duration, discard=a.discard, **model)
    th = prior.lo + qmc.Sobol(prior.ndim, scramble=True, seed=a.seed).random(a.n) * prior.width
    rows, failed, still = [], 0, 0
    t0 = time.perf_counter()
    for i, t in enumerate(th):
        y = recording(t, prior, cfg, sigma=a.sigma, seed=i)
        if y is None:
            failed += 1
            print(f"{i:3d} {np.round(t, 1)} simulation failed", flush=True)
            continue
        try:
            pb = Problem(y, 2000.0, prior, config=cfg)
        except ValueError:
            still += 1
            print(f"{i:3d} {np.round(t, 1)} no oscillation", flush=True)
            continue
        s = sensitivity(pb, t, seed=i)
        rows.append((t, s))
        print(
            f"{i:3d} {np.round(t, 1)} roughness {s.max_change:.3g} nats, second difference "
            f"{s.max_second_difference:.3g}, aperiodicity {s.aperiodicity:.3g}"
            f"{'  IRREGULAR' if s.irregular else ''}{'  ROUGH' if s.rough else ''}",
            flush=True,
        )
    names = prior.names
    p = np.array([t[names.index("p_sub")] for t, _ in rows])
    irr = np.array([s.irregular for _, s in rows], dtype=bool)
    rough = np.array([s.rough for _, s in rows], dtype=bool)
    print(
        f"\n{a.n} draws: {failed} failed, {still} did not oscillate, {len(rows)} oscillated, "
        f"{int(irr.sum())} irregular, {int(rough.sum())} rough, {int((irr | rough).sum())} either "
        f"({time.perf_counter() - t0:.0f} s)"
    )
    for lo, hi in BANDS:
        m = (p >= lo) & (p < hi)
        print(
            f"  p_sub {lo:6.0f}-{hi:6.0f} Pa: {int(irr[m].sum())} irregular, {int(rough[m].sum())} rough, "
            f"{int((irr | rough)[m].sum())} either, of {int(m.sum())}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
