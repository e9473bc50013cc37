"""f0 and mean peak glottal area at Table 3 vs time step and vs mesh, with observed orders.

Observed order from three successive refinements (ratio 2 in dt):
p = log2(|q1 - q2| / |q2 - q3|); 'n/a' when the differences do not shrink.
Usage: OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_convergence.py
"""

from __future__ import annotations

import math
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from vfcore import TABLE3, SimConfig, simulate  # noqa: E402
from vfcore.solver.system import get_system  # noqa: E402


def _order(q, ratio=2.0):
    out = []
    for a, b, c in zip(q[:-2], q[1:-1], q[2:]):
        d1, d2 = abs(a - b), abs(b - c)
        out.append(math.log(d1 / d2) / math.log(ratio) if d2 > 0 and d1 > d2 else float("nan"))
    return out


def _row(label, r):
    pk = r.cycles.peak_area
    return label, r.f0, pk.mean(), pk.std() / pk.mean(), r.cycles.min_area.mean()


def main() -> None:
    simulate(TABLE3, SimConfig(duration=0.01, discard=0.0))  # JIT warm-up
    print("Time step (medium mesh, Table 3, 550 ms, last 300 ms kept)")
    print(f"{'dt (s)':>10s} {'f0 (Hz)':>9s} {'peak (mm2)':>11s} {'cv peak':>8s} {'min (mm2)':>9s}")
    dts = [1e-4, 5e-5, 2.5e-5, 1.25e-5]
    rows = [_row(dt, simulate(TABLE3, SimConfig(dt=dt))) for dt in dts]
    for dt, f0, pk, cv, mn in rows:
        print(f"{dt:10.2e} {f0:9.3f} {pk:11.3f} {cv:8.4f} {mn:9.3f}")
    f0s = [r[1] for r in rows]
    pks = [r[2] for r in rows]
    print("observed order f0  :", ", ".join(f"{o:.2f}" for o in _order(f0s)))
    print("observed order peak:", ", ".join(f"{o:.2f}" for o in _order(pks)))
    # transient waveform (first 10 ms, before cycle-to-cycle variability), sup-norm differences
    g = [simulate(TABLE3, SimConfig(dt=dt, duration=0.01, discard=0.0, fps=10000)).gaw for dt in dts]
    d = [np.abs(g[i] - g[i + 1]).max() for i in range(len(g) - 1)]
    print("transient GAW (0-10 ms) max differences (mm2):", ", ".join(f"{x:.4f}" for x in d))
    print("  observed orders:", ", ".join(f"{math.log2(d[i] / d[i + 1]):.2f}" for i in range(len(d) - 1)))
    print()
    print("Mesh (dt 5e-5, Table 3)")
    print(
        f"{'mesh':>8s} {'tri':>5s} {'dofs':>5s} {'f0 (Hz)':>9s} {'peak (mm2)':>11s} {'cv peak':>8s} {'min (mm2)':>9s}"
    )
    mrows = []
    for m in ("coarse", "medium", "fine"):
        s = get_system(m, 0.4995)
        lab, f0, pk, cv, mn = _row(m, simulate(TABLE3, SimConfig(mesh=m)))
        mrows.append((s.mesh.n_triangles, f0, pk))
        print(f"{m:>8s} {s.mesh.n_triangles:5d} {s.n:5d} {f0:9.3f} {pk:11.3f} {cv:8.4f} {mn:9.3f}")
    # meshes are not nested; use h ~ 1/sqrt(n_tri) and the generalised Richardson estimate
    h = [1 / math.sqrt(t) for t, _, _ in mrows]
    for name, k in (("f0", 1), ("peak", 2)):
        q = [r[k] for r in mrows]
        d1, d2 = q[0] - q[1], q[1] - q[2]
        if d1 * d2 > 0 and abs(d1) > abs(d2):
            # solve (h1^p - h2^p) / (h2^p - h3^p) = d1 / d2 for p by bisection
            f = lambda p: (h[0] ** p - h[1] ** p) / (h[1] ** p - h[2] ** p) - d1 / d2  # noqa: E731
            lo, hi = 0.05, 10.0
            if f(lo) * f(hi) < 0:
                for _ in range(100):
                    mid = 0.5 * (lo + hi)
                    lo, hi = (mid, hi) if f(lo) * f(mid) > 0 else (lo, mid)
                print(f"mesh observed order {name}: {0.5 * (lo + hi):.2f}")
                continue
        print(f"mesh observed order {name}: n/a (differences {d1:+.3f}, {d2:+.3f} do not shrink monotonically)")


if __name__ == "__main__":
    main()
