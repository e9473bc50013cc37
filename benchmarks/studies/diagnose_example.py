"""The worked example of :ref:`diagnose`: wrong fixed parameters and a real left-out effect, before and after.

A recording of the model with eta and E_lig far from Table 3 (1.5 Poise and 2.6 kPa against 3.079 and 1.808)
and a constant 1.2 mm^2 glottal leak, camera noise 0.3 mm^2. The base model estimates E_body, E_cover and
p_sub with the rest at Table 3, as the diagnosis did before material-first:

- before: ``free_material=False, max_rms_ratio=None, floor_stop=False`` (the pipeline as it was);
- after: the defaults (the held parameters freed first, the 'no fit' check, the floor stop).

Small settings so it runs in minutes on 2 cores (coarse mesh, 0.35 s simulated, 200 frames, 16 particles,
four candidate entries, no continuation search); the verdicts, residuals and costs are printed.

    python benchmarks/studies/diagnose_example.py [--workers 2]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402

FPS = 2000.0
TRUTH = {"eta": 1.5, "E_lig": 2.6, "E_cover": 520.0}
LEAK_MM2 = 1.2
NOISE = 0.3
SETTINGS = dict(
    n_particles=16,
    refit_particles=None,
    seed=1,
    candidates=["leak", "scale", "frame_rate", "sep_ratio"],
    base_runs=1,
    continuation=False,
    continuation_entries=None,
)


def recording():
    from vfcore import SimConfig, simulate
    from vfcore.params import TABLE3, Params
    from vfcore.result import HR_OVERSAMPLE

    cfg = SimConfig(mesh="coarse", dt=1e-4, duration=0.35, discard=0.15)
    r = simulate(Params(**{**TABLE3.as_dict(), **TRUTH}), cfg)
    clean = np.asarray(r.gaw_hr[37::HR_OVERSAMPLE][:200])
    return clean + LEAK_MM2 + NOISE * np.random.default_rng(7).standard_normal(clean.size), cfg


def problem(y, cfg):
    from vfcore.inference import Prior
    from vfcore.inference.problem import Problem
    from vfcore.params import PARAM_NAMES, TABLE3

    fixed = {n: getattr(TABLE3, n) for n in PARAM_NAMES if n not in ("E_body", "E_cover", "p_sub")}
    return Problem(y, FPS, Prior.default(fixed=fixed), config=cfg)


def show(label: str, rep, wall: float) -> None:
    d = rep.to_dict()
    print(f"{label}: {rep.verdict}")
    print(
        f"  base residual RMS {d['base']['residual_rms']:.3f} mm^2 (noise estimate "
        f"{d['base']['predictive_noise_sd']:.3f}); {rep.n_simulations} simulations, {wall:.0f} s"
    )
    for r in d["ranking"]:
        print(
            f"  {r['name']:10s} dlogZ {r['delta']:10.1f} +- {r['delta_se']:6.1f}  RMS {100 * r['rms_gain']:5.1f} % lower"
            + ("  found" if r["found"] else f"  [{r['reason'].split(':')[0]}]")
        )
    if d.get("material"):
        m = d["material"]
        print(
            f"  material: freed {m['freed']}, dlogZ {m['delta']:.1f} +- {m['delta_se']:.1f}, RMS "
            f"{100 * m['rms_gain']:.0f} % lower, found={m['found']}; freed posterior "
            + ", ".join(f"{k} {v['mean']:.3g} +- {v['sd']:.2g}" for k, v in m["free"]["params"].items())
        )
    by = (d.get("cost") or {}).get("by_stage") or {}
    print("  time by stage: " + ", ".join(f"{k} {v['wall_s']:.0f} s" for k, v in by.items()))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)
    from concurrent.futures import ProcessPoolExecutor

    from vfcore.diagnose.pipeline import diagnose

    y, cfg = recording()
    pb = problem(y, cfg)
    print(f"truth: {TRUTH} (Table 3 elsewhere), leak {LEAK_MM2} mm^2, noise {NOISE} mm^2; estimated {pb.prior.names}")
    with ProcessPoolExecutor(a.workers) as ex:
        kw = dict(SETTINGS, map=ex.map, chunk_size=8)
        t0 = time.perf_counter()
        before = diagnose(pb, free_material=False, max_rms_ratio=None, floor_stop=False, **kw)
        show("before", before, time.perf_counter() - t0)
        t0 = time.perf_counter()
        after = diagnose(pb, **kw)
        show("after", after, time.perf_counter() - t0)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
