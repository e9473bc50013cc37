"""The log-likelihood along the line from a calibration twin's fitted posterior mean to its truth.

Where a fit misses its truth although the truth scores as well as the best particle, is the likelihood
between them a hill (a posterior sampled too thinly) or a staircase of plateaus (a likelihood no local
sampler can describe)? Reads one row of ``bench_calibration.py``'s ``calibration.json``, rebuilds that twin
(same seed, noise and model, which must be given as they were to the calibration), and prints the
log-likelihood at points ``exp(log mean + s (log truth - log mean))``, s from -0.25 to 1.25, with the limit
cycle's autocorrelation f0 beside it (whether the period moves with the jumps). Points are simulated one by one
with ``simulate`` rather than ``vfcore.inference.evaluate``, because the f0 is wanted too. The prior is the
paper's Table 2 box with the calibration's fixed parameters at Table 3 (``--prior-set human`` calibrations are
not supported; the truth check below refuses them).

    python benchmarks/studies/scan_fit_to_truth.py DIR/calibration.json --dataset 0 --seed 2000 --dt 5e-5 --contact layer
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import warnings
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("calibration", help="calibration.json of bench_calibration.py")
    ap.add_argument("--dataset", type=int, required=True, help="the twin's index (its seed is --seed + index)")
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--mesh", default="coarse")
    ap.add_argument("--dt", type=float, default=1e-4)
    ap.add_argument("--duration", type=float, default=0.55)
    ap.add_argument("--contact", default="projection")
    ap.add_argument("--sigma-e", type=float, default=1.0)
    ap.add_argument("--n-obs", type=int, default=400)
    ap.add_argument("--points", type=int, default=61)
    a = ap.parse_args(argv)
    from vfcore import simulate
    from vfcore.config import SimConfig
    from vfcore.inference import Prior, make_twin
    from vfcore.inference.scoring import aligned_loglik
    from vfcore.params import PARAM_NAMES, TABLE3

    data = json.loads(Path(a.calibration).read_text())
    rows = [r for r in data["rows"] if r["dataset"] == a.dataset]
    if not rows:
        ap.error(f"{a.calibration} has no twin {a.dataset}")
    row = rows[0]
    values = TABLE3.as_dict()
    prior = Prior.default(fixed={n: values[n] for n in PARAM_NAMES if n not in data["names"]})
    cfg = SimConfig(mesh=a.mesh, dt=a.dt, duration=a.duration, contact=a.contact)
    tw = make_twin(prior, cfg, seed=a.seed + a.dataset, sigma_e=a.sigma_e, n_obs=a.n_obs)
    if not np.allclose(tw.truth, row["truth"]):
        ap.error("the rebuilt twin's truth differs from the row's: give the calibration's --seed, model and noise")
    lm, lt = np.log(np.asarray(row["mean"])), np.log(tw.truth)
    print(
        f"twin {a.dataset}: loglik of the truth {row['loglik_truth']:.1f}, "
        f"of the best particle {row['loglik_best']:.1f}"
    )
    print("| s (0 = posterior mean, 1 = truth) | log-likelihood | f0 (Hz) |")
    print("|---|---|---|")
    for s in np.linspace(-0.25, 1.25, a.points):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = simulate(prior.to_params(np.exp(lm + s * (lt - lm))), cfg)
        ll = aligned_loglik(np.asarray(r.gaw_hr, dtype=float), tw.problem, r.params)[0] if r.ok else -np.inf
        print(f"| {s:+.3f} | {ll:.1f} | {r.f0:.3f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
