"""What anchoring the common scale does to a six-parameter FE fit and to the products it reports.

One twin (truth at Table 3 unless --truth-seed draws one from the Table 2 box; x0 fixed), fitted by SMC with
all six scaled parameters free and with each anchor in turn:

* none: the common scale is set by the prior's box (the exact symmetry of :ref:`inference`);
* p_sub measured with a relative sd of 5 % and of 1 % (``Problem.measurements``; the measured value is the
  truth plus a draw of its error, so the anchor is an honest noisy measurement);
* rho fixed at the truth (``--fix rho``): the five others free, no symmetry left.

For each it prints the simulations and wall time, the identifiability summary (the common factor's sd in log,
the least narrowed principal direction, the scale-invariant combinations) and the 90 % intervals of the
contact pressure while in contact, the contact impulse per cycle and the mean flow rate, with whether they
cover the truth's values.

    python benchmarks/studies/bench_anchor.py --particles 100 --workers 2
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402

from vfcore.config import SimConfig  # noqa: E402
from vfcore.inference import Prior, Problem, evaluate, identify, make_twin, smc  # noqa: E402
from vfcore.params import TABLE3  # noqa: E402

PRODUCTS = (
    ("contact_pressure_in_contact", "contact pressure in contact", "Pa", 1.0),
    ("contact_impulse", "contact impulse per cycle", "mN s/m", 1e3),
    ("mean_flow", "flow rate Q", "mL/s", 1e6),
)


def _interval(x: np.ndarray, level: float = 0.9) -> tuple[float, float, float]:
    q = (1.0 - level) / 2.0
    return float(np.median(x)), float(np.quantile(x, q)), float(np.quantile(x, 1.0 - q))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mesh", default="coarse")
    ap.add_argument("--dt", type=float, default=1e-4)
    ap.add_argument("--particles", type=int, default=100)
    ap.add_argument("--sigma-e", type=float, default=1.0)
    ap.add_argument("--truth-seed", type=int, default=None, help="draw the truth from the box (default: Table 3)")
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    a = ap.parse_args(argv)

    cfg = SimConfig(mesh=a.mesh, dt=a.dt, duration=0.55)
    six = Prior.default(fixed={"x0": TABLE3.x0})
    truth = None if a.truth_seed is not None else np.array([getattr(TABLE3, n) for n in six.names])
    tw = make_twin(six, cfg, seed=a.truth_seed if a.truth_seed is not None else a.seed, sigma_e=a.sigma_e, truth=truth)
    t_true = dict(zip(six.names, tw.truth))
    ev_true = evaluate(tw.truth[None, :], tw.problem)
    rng = np.random.default_rng(a.seed)
    runs = [("none", tw.problem)]
    for rel in (0.05, 0.01):
        sd = rel * t_true["p_sub"]
        m = t_true["p_sub"] + sd * rng.standard_normal()
        runs.append(
            (
                f"p_sub measured +-{rel:.0%} ({m:.0f} +- {sd:.0f} Pa)",
                Problem.from_dict({**tw.problem.to_dict(), "measurements": {"p_sub": [m, sd]}}),
            )
        )
    five = Prior.default(fixed={"x0": TABLE3.x0, "rho": t_true["rho"]})
    runs.append(
        (
            f"rho fixed at the truth ({t_true['rho']:.0f})",
            Problem.from_dict({**tw.problem.to_dict(), "prior": five.to_dict()}),
        )
    )

    pool = None
    if a.workers > 1:
        import multiprocessing as mp

        pool = mp.get_context("spawn").Pool(a.workers)
    mapper = pool.imap if pool is not None else map
    print(
        f"twin: {', '.join(f'{n} {v:.4g}' for n, v in t_true.items())}; mesh {a.mesh}, dt {a.dt:g} s, "
        f"sigma_e {a.sigma_e} mm^2, {a.particles} particles, {a.workers} workers"
    )
    print(
        "truth's products: "
        + "; ".join(f"{label} {getattr(ev_true, key)[0] * f:.4g} {u}" for key, label, u, f in PRODUCTS)
    )
    try:
        for name, prob in runs:
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                post = smc(prob, n_particles=a.particles, seed=a.seed, map=mapper, chunk_size=16)
            wall = time.perf_counter() - t0
            idt = identify(post, prob.prior, prob.measurements)
            s = idt.scale or {}
            print(
                f"\n## anchor: {name}\n{post.n_simulations} simulations, {wall:.0f} s; "
                f"best particle log-likelihood {np.max(post.predictive.loglik):.1f} "
                f"(truth {ev_true.loglik[0]:.1f})"
            )
            log_c = s.get("log_c_sd")
            print(
                f"sd of the common factor (log): {log_c:.3g}"
                if log_c is not None
                else "no common scale left (one of the six fixed)"
            )
            lead = idt.principal[0] if idt.principal else None
            if lead:
                load = ", ".join(f"{n} {v:+.2f}" for n, v in lead["loadings"].items() if abs(v) >= 0.2)
                print(
                    f"least narrowed direction: sd {lead['sd']:.3g} / prior {lead['prior_sd']:.3g} "
                    f"(ratio {lead['ratio']:.2f}): {load}"
                )
            for key, label, unit, f in PRODUCTS:
                x = getattr(post.predictive, key) * f
                med, lo, hi = _interval(x[np.isfinite(x)])
                tv = getattr(ev_true, key)[0] * f
                print(
                    f"{label:<28} {med:9.4g} {unit:<7} 90%: {lo:.4g} .. {hi:.4g}  (width {100 * (hi - lo) / med:5.1f} % "
                    f"of the median; truth {tv:.4g} {'inside' if lo <= tv <= hi else 'OUTSIDE'})"
                )
    finally:
        if pool is not None:
            pool.close()
            pool.join()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
