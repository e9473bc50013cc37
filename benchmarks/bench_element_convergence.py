"""Mesh convergence at Table 3 for both elements ("p1", "anp"): eigenfrequencies and the limit cycle.

Meshes: the three shipped ones (coarse 174, medium 210, fine 268 triangles) and, with --refined,
gmsh meshes of the same geometry at smaller characteristic lengths (vfcore.mesh.geometry.build_mesh).
For each: the three lowest undamped eigenfrequencies (Table 3 moduli and density) and a 550-ms
simulation at dt = 5e-5 s (last 300 ms kept): f0 (autocorrelation, vfcore.measures.estimate_f0),
mean cycle peak area (cycle maxima between the minima of vfcore.measures.cycle_boundaries),
peak-to-peak of the last 100 ms, and the regime (oscillating when p2p > 0.5 mm^2 and f0 finite).

Usage: OMP_NUM_THREADS=1 python benchmarks/bench_element_convergence.py [--refined 0.6,0.43:5,0.3]
       [--sep-ratio 1.3]   (--refined: gmsh lc in mm, optionally ':algorithm', default algorithm 6)
"""

from __future__ import annotations

import argparse
import math
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import scipy.linalg as sl  # noqa: E402

import vfcore.forward as fw  # noqa: E402
from vfcore import TABLE3, SimConfig, simulate  # noqa: E402
from vfcore.config import ELEMENTS  # noqa: E402
from vfcore.measures import cycle_boundaries, estimate_f0  # noqa: E402
from vfcore.mesh import load_mesh, make_fold_mesh  # noqa: E402
from vfcore.solver.system import build_system, get_system  # noqa: E402


def eigenfrequencies(s, k=3) -> np.ndarray:
    si = TABLE3.si()
    K = s.matrix(s.stiffness_values((si["E_body"], si["E_lig"], si["E_cover"]))).toarray()
    M = s.matrix(si["rho"] * s.m_vals).toarray()
    w = sl.eigh(K, M, eigvals_only=True, subset_by_index=[0, k - 1])
    return np.sqrt(w) / (2 * math.pi)


def limit_cycle(s, element: str, sep_ratio: float = 1.3) -> dict:
    """Table 3 simulation on system ``s`` (injected in place of the cached named-mesh system)."""
    orig = fw.get_system
    fw.get_system = lambda *a: s  # noqa: E731
    try:
        t0 = time.perf_counter()
        r = simulate(TABLE3, SimConfig(element=element, sep_ratio=sep_ratio))
        wall = time.perf_counter() - t0
    finally:
        fw.get_system = orig
    if not r.ok:
        return dict(ok=False, msg=r.message, wall=wall)
    g = r.gaw
    last = g[-int(round(0.1 * r.fps)) :]
    f0 = estimate_f0(g, r.fps)
    b = cycle_boundaries(g, r.fps, f0) if np.isfinite(f0) else np.zeros(0, int)
    pk = np.array([g[i : j + 1].max() for i, j in zip(b[:-1], b[1:])]) if b.size > 1 else np.array([g.max()])
    return dict(
        ok=True,
        f0=f0,
        f0_cyc=r.f0,
        peak=pk.mean(),
        peak_cv=pk.std() / pk.mean() if pk.mean() > 0 else 0,
        p2p=np.ptp(last),
        amin=last.min(),
        osc=bool(np.ptp(last) > 0.5 and np.isfinite(f0)),
        wall=wall,
    )


def observed_order(h, q):
    """Order p from three (h, q) with non-uniform ratios: (h1^p - h2^p)/(h2^p - h3^p) = d1/d2."""
    d1, d2 = q[0] - q[1], q[1] - q[2]
    if not (d1 * d2 > 0 and abs(d1) > abs(d2)):
        return float("nan")
    f = lambda p: (h[0] ** p - h[1] ** p) / (h[1] ** p - h[2] ** p) - d1 / d2  # noqa: E731
    lo, hi = 0.05, 12.0
    if f(lo) * f(hi) > 0:
        return float("nan")
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(lo) * f(mid) > 0 else (lo, mid)
    return 0.5 * (lo + hi)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--refined", default="", help="comma-separated gmsh characteristic lengths (mm)")
    ap.add_argument("--elements", default=",".join(ELEMENTS))
    ap.add_argument("--sep-ratio", type=float, default=1.3)
    a = ap.parse_args()
    meshes = [(n, load_mesh(n)) for n in ("coarse", "medium", "fine")]
    if a.refined:
        from vfcore.mesh.geometry import build_mesh

        for item in a.refined.split(","):
            lc, _, alg = item.partition(":")
            pts, tri, lay = build_mesh(float(lc), algorithm=int(alg or 6))
            meshes.append((f"lc{item}", make_fold_mesh(pts, tri, lay, name=f"lc{item}")))
    simulate(TABLE3, SimConfig(duration=0.01, discard=0.0))  # JIT warm-up
    for el in a.elements.split(","):
        print(f"\nelement {el} (nu 0.4995, Table 3, sep_ratio {a.sep_ratio}, dt 5e-5 s, 550 ms, last 300 ms)")
        print(
            f"{'mesh':>9s} {'tri':>5s} {'dofs':>5s} {'nnzL':>6s} {'eig1-3 (Hz)':>20s} {'regime':>7s} {'f0 (Hz)':>8s} "
            f"{'f0cyc':>6s} {'peak':>6s} {'cv':>5s} {'p2p100':>7s} {'min':>6s} {'wall s':>6s}"
        )
        rows = []
        for name, mesh in meshes:
            s = get_system(name, 0.4995, el) if name in ("coarse", "medium", "fine") else build_system(mesh, 0.4995, el)
            ev = eigenfrequencies(s)
            lc = limit_cycle(s, el, a.sep_ratio)
            ev_s = ", ".join(f"{x:5.1f}" for x in ev)
            if not lc["ok"]:
                print(f"{name:>9s} {mesh.n_triangles:5d} {s.n:5d} {s.nnz_factor:6d} {ev_s:>20s}  failed: {lc['msg']}")
                continue
            reg = "osc" if lc["osc"] else ("open" if lc["amin"] > 0 else "closed")
            print(
                f"{name:>9s} {mesh.n_triangles:5d} {s.n:5d} {s.nnz_factor:6d} {ev_s:>20s} {reg:>7s} {lc['f0']:8.2f} "
                f"{lc['f0_cyc']:6.2f} {lc['peak']:6.2f} {lc['peak_cv']:5.3f} {lc['p2p']:7.2f} {lc['amin']:6.2f} "
                f"{lc['wall']:6.2f}",
                flush=True,
            )
            if ":" not in name:
                rows.append((mesh.n_triangles, ev[0], lc["f0"], lc["peak"], lc["osc"]))
        # observed orders over the algorithm-6 sequence (shipped meshes and lc without ':alg')
        if len(rows) >= 3:
            h = [1 / math.sqrt(r[0]) for r in rows]
            for k, lab in ((1, "eig1"), (2, "f0"), (3, "peak")):
                q = [r[k] for r in rows]
                orders = [
                    observed_order(h[i : i + 3], q[i : i + 3])
                    if (k == 1 or all(r[4] for r in rows[i : i + 3]))
                    else float("nan")
                    for i in range(len(q) - 2)
                ]
                print(
                    f"  observed order {lab:>4s} (h ~ 1/sqrt(tri), successive algorithm-6 triples; n/a: not "
                    "monotone or not oscillating): " + ", ".join("n/a" if math.isnan(o) else f"{o:.2f}" for o in orders)
                )


if __name__ == "__main__":
    main()
