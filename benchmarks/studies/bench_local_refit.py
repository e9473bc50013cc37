"""Does a local least-squares fit reach the truth on the continuous model? A measurement for the diagnosis's
local refits (Gauss-Newton / Levenberg-Marquardt on the whitened residual, in place of global SMC).

Protocol: the calibration twins of ``bench_smoothness.py`` (``make_twin`` seeds 1000 + i; six parameters free,
x0 at Table 3; coarse mesh, dt 5e-5 s, the compliant layer, ``flow="continuous"``; noise 1 mm^2) for the twins in
``--twins``; a start drawn at the truth times exp(0.05 z), z standard normal (seeded by the twin); scipy's
``least_squares`` (trust-region reflective) on the aligned residual (simulation minus observation, divided by the
noise sd) in log parameters, forward-difference Jacobian with a relative step of 1e-3, at most ``--max-nfev``
function evaluations (the Jacobian's simulations not counted by scipy; all are counted here). Printed per twin:
half the residual sum of squares at the start, at the fit and at the truth (the negative log-likelihood up to a
constant), the largest log-distance from the fit to the truth, simulations and wall time.

    OMP_NUM_THREADS=1 python benchmarks/bench_local_refit.py --twins 0,1,2,9,5,12
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--twins", default="0,1,2,9,5,12")
    ap.add_argument("--max-nfev", type=int, default=40)
    ap.add_argument("--flow", default="continuous")
    ap.add_argument("--contact", default="layer")
    a = ap.parse_args(argv)
    from scipy.optimize import least_squares

    from vfcore.config import SimConfig
    from vfcore.inference import Prior, evaluate, make_twin
    from vfcore.params import TABLE3

    cfg = SimConfig(mesh="coarse", dt=5e-5, duration=0.55, contact=a.contact, flow=a.flow)
    prior = Prior.default(fixed={"x0": TABLE3.as_dict()["x0"]})
    print("| twin | half RSS: start | fit | truth | max abs log(fit / truth) | simulations | wall (s) |")
    print("|---|---|---|---|---|---|---|")
    for i in (int(x) for x in a.twins.split(",")):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tw = make_twin(prior, cfg, seed=1000 + i, sigma_e=1.0, n_obs=400)
            pb = tw.problem
            obs = pb.obs_compared
            n_sim = [0]

            def residual(z):
                ev = evaluate(np.exp(z)[None, :], pb)
                n_sim[0] += 1
                return (np.asarray(ev.gaw[0], float) - obs) if ev.ok[0] else np.full(obs.size, 50.0)

            zt = np.log(tw.truth)
            z0 = zt + 0.05 * np.random.default_rng(i).standard_normal(zt.size)
            t = time.perf_counter()
            fit = least_squares(residual, z0, method="trf", diff_step=1e-3, max_nfev=a.max_nfev)
            wall = time.perf_counter() - t
            sims = n_sim[0]
            half = [0.5 * float(np.sum(r**2)) for r in (residual(z0), fit.fun, residual(zt))]
        print(
            f"| {i} | {half[0]:.1f} | {half[1]:.1f} | {half[2]:.1f} | {np.max(np.abs(fit.x - zt)):.3f} | {sims} | "
            f"{wall:.0f} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
