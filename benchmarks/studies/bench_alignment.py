"""What a profile alignment costs, and what that costs an integrated catalogue entry.

An integrated extension (leak, zipper, asymmetry, frame rate, ...) scores each forward simulation
at a few hundred quadrature nodes, and each node is one profile alignment over every tenth-of-a-
frame lag (:ref:`diagnose-cost-integrated-parameters`), so alignment is most of that entry's cost
beyond the simulation. Printed:

1. ms per alignment score vector, for the library's FFT form (``vfcore.observe._profile_scores``)
   and for one ``np.correlate`` per sub-frame residue (the baseline, kept here), at the benchmark suite's window (400 frames, 200 lags, 10 fine steps a
   frame), with the largest difference between the two (relative to the scores);
2. seconds per simulation spent integrating the leak's two parameters out (24 x 6 cells and
   their refinement) on a synthetic oscillating record, and the number of alignments that took;
3. ms per zipper observation (24 delayed strips of a 6,000-sample record): the fused kernel
   (``vfcore.diagnose._kernels.strip_sum``) against shifting and adding each strip with
   numpy (``vfcore.diagnose.observers.delayed_copy``, the baseline), with their largest difference.

Usage: python benchmarks/studies/bench_alignment.py [--repeats 300]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402


def correlate_scores(hr: np.ndarray, tmpl: np.ndarray, q: int, j_max: int) -> np.ndarray:
    """The baseline: per residue r, one ``np.correlate`` of ``hr[r::q]`` with the
    template and a running sum of its squares (the baseline)."""
    n = tmpl.size
    cs = np.empty(j_max + 1)
    o2 = float(tmpl @ tmpl)
    for r in range(min(q, j_max + 1)):
        kmax = (j_max - r) // q
        x = hr[r::q][: kmax + n]
        c = np.correlate(x, tmpl, "valid")
        e = np.concatenate([[0.0], np.cumsum(x * x)])
        cs[r::q] = -(e[n : n + kmax + 1] - e[: kmax + 1] - 2.0 * c + o2)
    return cs


def _record(n_frames: int, q: int, seed: int = 0, fps: float = 4000.0) -> np.ndarray:
    """A glottal-like oversampled area: a half-rectified 130 Hz sine, slowly growing."""
    t = np.arange(q * n_frames) / (q * fps)
    rng = np.random.default_rng(seed)
    return (8 + 2 * t / t[-1]) * np.maximum(np.sin(2 * np.pi * 130 * t), 0) ** 1.5 + 0.01 * rng.standard_normal(t.size)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=300)
    a = ap.parse_args(argv)
    from vfcore.observe import _profile_scores

    q, n, lags = 10, 400, 200
    hr = _record(n + lags + 1, q)
    rng = np.random.default_rng(1)
    tmpl = hr[1234::q][:n] + 0.5 * rng.standard_normal(n)
    j_max = q * lags
    fast, base = _profile_scores(hr, tmpl, q, j_max), correlate_scores(hr, tmpl, q, j_max)
    print(
        f"window {n} frames, {lags} lags x {q} fine steps; largest difference "
        f"{np.max(np.abs(fast - base)) / np.max(np.abs(base)):.1e} of the scores; "
        f"best lag {int(np.argmax(fast))} / {int(np.argmax(base))} (true 1234)"
    )
    for label, f in (("np.correlate per residue (baseline)", correlate_scores), ("FFT (library)", _profile_scores)):
        f(hr, tmpl, q, j_max)
        t0 = time.perf_counter()
        for _ in range(a.repeats):
            f(hr, tmpl, q, j_max)
        print(f"{label:38s} {1e3 * (time.perf_counter() - t0) / a.repeats:7.3f} ms per alignment")

    # the leak's integration over one simulation, as ExtendedEvaluator does it
    from vfcore.config import SimConfig
    from vfcore.diagnose import quadrature as quad
    from vfcore.diagnose.extensions import get
    from vfcore.diagnose.fit import observer, quad_cells
    from vfcore.inference import Prior
    from vfcore.inference.problem import Problem, aligned_loglik

    fps = 2000.0  # the suite's: 600 simulated frames, 200 lags
    cfg = SimConfig(duration=0.55, discard=0.25, fps=fps)
    sim = _record(601, q, seed=2, fps=fps)
    o = sim[1234::q][:n]
    obs = o + np.maximum(0.0, 1.2 - 0.2 * o) + 0.5 * rng.standard_normal(n)
    pb = Problem(obs, fps, Prior.default(), sigma_e=1.0, config=cfg)
    names = get("leak").integrable
    lo = np.array([get("leak").bounds()[k][0] for k in names])
    hi = np.array([get("leak").bounds()[k][1] for k in names])
    look = observer("leak", sim, fps)
    count = [0]

    def fn(points):
        count[0] += len(points)
        return np.array([aligned_loglik(look(dict(zip(names, map(float, p)))), pb)[0] for p in points])

    import vfcore.observe as V

    reps = max(1, a.repeats // 60)
    out = {}
    for label, f in (("baseline", correlate_scores), ("library", _profile_scores)):
        V._profile_scores = f
        count[0] = 0
        t0 = time.perf_counter()
        for _ in range(reps):
            res = quad.integrate_loglik(fn, lo, hi, n0=quad_cells("leak", len(names)))
        out[label] = res
        print(
            f"leak integrated out of one simulation, {label:8s}: {1e3 * (time.perf_counter() - t0) / reps:6.1f} ms, "
            f"{count[0] // reps} alignments (window {pb.window}); leak {res.mean[0]:.3f} +- {res.sd[0]:.3f} mm^2 "
            f"(generated 1.2), log marginal likelihood {res.log_mean:.6f}"
        )
    V._profile_scores = _profile_scores

    # the zipper's strips
    from vfcore.diagnose._kernels import strip_sum
    from vfcore.diagnose.observers import delayed_copy

    y = _record(600, q, seed=3)
    delays = 40.0 * ((np.arange(24) + 0.5) / 24 - 0.5)  # a lag of 40 samples end to end
    weights = np.full(24, 1 / 24)
    pad = 42
    yp = np.concatenate([np.full(pad, y[0]), y, np.full(pad, y[-1])])

    def shifted():
        out = np.zeros_like(y)
        for d, w in zip(delays, weights):
            out += w * delayed_copy(yp, pad, y.size, d)
        return out

    diff = np.max(np.abs(strip_sum(y, delays, weights) - shifted())) / np.max(np.abs(shifted()))
    for label, f in (
        ("numpy shift and add (baseline)", shifted),
        ("fused kernel (library)", lambda: strip_sum(y, delays, weights)),
    ):
        f()
        t0 = time.perf_counter()
        for _ in range(a.repeats):
            f()
        print(
            f"zipper, 24 strips of {y.size} samples, {label:31s} {1e3 * (time.perf_counter() - t0) / a.repeats:7.3f} ms"
        )
    print(f"zipper: largest difference {diff:.1e} of the observed area")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
