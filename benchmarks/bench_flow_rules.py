"""The paper's node-wise flow load against the continuous one, in one run: Table 3 on the shipped meshes and the
cost of a simulation.

Protocol: Table 3's parameters, 0.55 s with 0.25 s discarded, each mesh in ``--meshes`` at ``--dt``; for each
(flow, contact) pair of ``RULES`` the model's f0 (Hz), peak and trough of the kept GAW (mm^2), closed quotient
and contact impulse per cycle (means over the kept cycles). Then the cost: ``--n`` prior-box draws (seed 3,
the box of ``bench_batch.py``) simulated by the lock-step kernel in blocks of ``--block`` on one core, best of
``--reps`` runs, per rule, interleaved (rule A, rule B, rule A, ...) so that a busy machine slows both alike.

    OMP_NUM_THREADS=1 python benchmarks/bench_flow_rules.py [--meshes coarse,medium,fine] [--dt 5e-5]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from benchmarks.bench_batch import HI, LO  # noqa: E402  (the prior box of the lock-step benchmark)

RULES = (("paper", "projection"), ("paper", "layer"), ("continuous", "layer"))


def table3(meshes, dt) -> None:
    from vfcore import TABLE3, SimConfig, simulate

    print(
        "| mesh | flow | contact | f0 (Hz) | peak (mm²) | trough (mm²) | closed quotient | contact impulse (mN s/m) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for mesh in meshes:
        for flow, contact in RULES:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                r = simulate(TABLE3, SimConfig(mesh=mesh, dt=dt, flow=flow, contact=contact))
            if not r.ok:
                print(f"| {mesh} | {flow} | {contact} | failed: {r.message} | | | | |")
                continue
            cq = np.nanmean(r.cycles.closed_quotient) if r.cycles.closed_quotient.size else float("nan")
            imp = np.nanmean(r.cycles.contact_impulse) * 1e3 if r.cycles.contact_impulse.size else float("nan")
            print(
                f"| {mesh} | {flow} | {contact} | {r.f0:.2f} | {np.max(r.gaw):.2f} | {np.min(r.gaw):.2f} | "
                f"{cq:.2f} | {imp:.3f} |",
                flush=True,
            )


def cost(mesh, dt, n, block, reps) -> None:
    from vfcore import Params, SimConfig
    from vfcore.batch import simulate_many

    rng = np.random.default_rng(3)
    rows = np.array([Params.from_array(r).as_array() for r in LO + (HI - LO) * rng.random((n, 7))])
    best = {rule: np.inf for rule in RULES}
    cfgs = {rule: SimConfig(mesh=mesh, dt=dt, flow=rule[0], contact=rule[1], early_stop=False) for rule in RULES}
    for rule in RULES:  # compile outside the timing
        simulate_many(rows[:block], cfgs[rule].replace(duration=0.01, discard=0.0), block=block)
    for _ in range(reps):
        for rule in RULES:
            t = time.perf_counter()
            simulate_many(rows, cfgs[rule], block=block)
            best[rule] = min(best[rule], (time.perf_counter() - t) / n)
    base = best[("paper", "projection")]
    print(f"\ncost, {mesh} mesh, dt {dt:g}, lock-step block {block}, {n} prior-box draws, best of {reps}, one core:")
    print("| flow | contact | ms per simulation | relative to paper + projection |")
    print("|---|---|---|---|")
    for rule in RULES:
        print(f"| {rule[0]} | {rule[1]} | {best[rule] * 1e3:.1f} | {best[rule] / base:.3f} |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--meshes", default="coarse,medium,fine")
    ap.add_argument("--dt", type=float, default=5e-5)
    ap.add_argument("--n", type=int, default=64)
    ap.add_argument("--block", type=int, default=32)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--cost-mesh", default="medium")
    ap.add_argument("--skip-table", action="store_true")
    a = ap.parse_args(argv)
    if not a.skip_table:
        table3(a.meshes.split(","), a.dt)
    if a.n > 0:
        cost(a.cost_mesh, a.dt, a.n, a.block, a.reps)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
