"""How often the tool flags a recording's likelihood rough, at the calibration twins' truths and over prior draws,
per flow rule.

Protocol: the twins of ``bench_smoothness.py`` (``make_twin`` seeds ``--seed`` + i, six parameters free, x0 at
Table 3, 400 frames at 2 kHz, noise 1 mm^2) for i < ``--twins``; then ``--draws`` prior draws (seed 4) that
phonate, each made a twin of itself (``make_twin(truth=...)``, the same noise). At each truth
:func:`vfcore.diagnose.regularity.sensitivity` (its defaults: the second difference of the log-likelihood at a
relative step of 1e-4 along two directions, and the aperiodicity of the simulated cycle) gives the flag. Printed
per rule: twins flagged, the largest second difference and aperiodicity among the unflagged, and the same over
the prior draws (those that do not phonate are counted apart).

    OMP_NUM_THREADS=1 python benchmarks/bench_rough_flag.py [--mesh coarse] [--dt 5e-5] [--draws 64]
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

RULES = (("paper", "projection"), ("continuous", "layer"))


def flags(prior, cfg, truths=None, seeds=()):
    from vfcore.diagnose.regularity import sensitivity
    from vfcore.inference import make_twin

    out, silent = [], 0
    items = [(s, None) for s in seeds] + [(4000 + k, t) for k, t in enumerate(truths if truths is not None else [])]
    for seed, truth in items:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                tw = make_twin(prior, cfg, seed=seed, sigma_e=1.0, n_obs=400, truth=truth)
            except (ValueError, RuntimeError):
                silent += 1
                continue
            s = sensitivity(tw.problem, tw.truth)
        out.append((s.rough, max(s.second_differences), s.aperiodicity))
    return out, silent


def report(name, rows, silent):
    rough = [r for r in rows if r[0]]
    calm = [r for r in rows if not r[0]]
    sd = max((r[1] for r in calm), default=float("nan"))
    ap = max((r[2] for r in calm if np.isfinite(r[2])), default=float("nan"))
    print(f"| {name} | {len(rough)} of {len(rows)} | {sd:.2f} | {ap:.2f} | {silent} |", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mesh", default="coarse")
    ap.add_argument("--dt", type=float, default=5e-5)
    ap.add_argument("--twins", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--draws", type=int, default=64)
    a = ap.parse_args(argv)
    from vfcore.config import SimConfig
    from vfcore.inference import Prior
    from vfcore.params import TABLE3

    prior = Prior.default(fixed={"x0": TABLE3.as_dict()["x0"]})
    draws = prior.sample(a.draws, np.random.default_rng(4))
    print(f"{a.mesh} mesh, dt {a.dt:g}: the rough flag of vfcore.diagnose.regularity.sensitivity")
    print(
        "| rule, truths | flagged rough | largest second difference unflagged (nats) | largest aperiodicity "
        "unflagged (nats) | not phonating |"
    )
    print("|---|---|---|---|---|")
    for flow, contact in RULES:
        cfg = SimConfig(mesh=a.mesh, dt=a.dt, flow=flow, contact=contact)
        rows, silent = flags(prior, cfg, seeds=[a.seed + i for i in range(a.twins)])
        report(f"{flow} + {contact}, {a.twins} twins", rows, silent)
        rows, silent = flags(prior, cfg, truths=draws)
        report(f"{flow} + {contact}, {a.draws} prior draws", rows, silent)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
