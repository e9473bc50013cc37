"""Does the limit cycle converge under mesh refinement? f0, opening and closure on six meshes, up to 15,000 triangles.

Protocol (:ref:`validation-model-mesh-convergence-not-reached-with`): the locking-free element (``element="anp"``, whose eigenfrequencies
converge) and the compliant contact layer (``contact="layer"``, whose pressures converge in the step), so that
neither the element nor the contact law is what fails to converge. dt 5e-5 s, 0.35 s simulated, the first 0.15 s
discarded. Parameters: Table 3, and two points inside the region where the three shipped meshes all oscillate
with anp (:ref:`validation-model-the-oscillation-map`): A = Table 3 with E_cover 850 Pa, p_sub 800 Pa; B = E_cover 950 Pa,
p_sub 1000 Pa; two louder ones where the 1,049-triangle mesh closes: C = E_cover 500 Pa, p_sub 1200 Pa; D = E_cover
700 Pa, p_sub 1400 Pa. ``--sep-ratio`` sets the flow's separation ratio (the Bernoulli pressure at the narrowest
gap is p_sub - sep_ratio^2 (p_sub - p_sup): a suction for any ratio above 1; 1.0 has none; default the model's).
Meshes: the five shipped ones, "x3fine", the M5 section meshed by gmsh at a characteristic length of 0.1 mm (about
15,000 triangles), and on request "x4fine" at 0.05 mm (about 60,000 triangles; a 0.35-s run takes about half an
hour on one core); neither is shipped, both are built here into a temporary folder. Per run: f0
(autocorrelation), the smallest and largest area of the kept window, the closed quotient, the contact impulse
per cycle and the pressure in contact (0 when the glottis does not close). ``--dt-check``: the finest two meshes
again at dt 2.5e-5 s. ``--epithelium E_KPA,H_MM`` adds the epithelium membrane (:ref:`model-extensions`).

    python benchmarks/bench_mesh_refinement.py             # ~10 min on one core, most of it x3fine
    python benchmarks/bench_mesh_refinement.py --elements anp,p1 --dt-check
    python benchmarks/bench_mesh_refinement.py --points "C,D,Table 3,A" --sep-ratio 1.0 \
        --meshes medium,xfine,xxfine,x3fine
    python benchmarks/bench_mesh_refinement.py --points C --sep-ratio 1.0 --meshes x4fine
    python benchmarks/bench_mesh_refinement.py --points "C,D,Table 3" --meshes xfine,xxfine,x3fine --epithelium 30,0.05
    python benchmarks/bench_mesh_refinement.py --points "Table 3,C,D" --meshes coarse,medium,fine,xfine,xxfine \
        --flow continuous
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

#: Meshes the benchmark builds (name: gmsh characteristic length, mm): measurement aids, not product options.
BUILT = {"x3fine": 0.1, "x4fine": 0.05}
SHIPPED = ("coarse", "medium", "fine", "xfine", "xxfine")


def register_built(folder: Path, names) -> None:
    """Build the meshes ``names`` of :data:`BUILT` into ``folder`` (with copies of the shipped meshes) and point this
    process's mesh loader and ``SimConfig`` at it."""
    import vfcore.config as config
    import vfcore.mesh as mesh
    from vfcore.mesh.geometry import build_mesh

    for name in SHIPPED:
        shutil.copy(mesh.DATA / f"{name}.npz", folder / f"{name}.npz")
    for name in names:
        pts, tri, lay = build_mesh(BUILT[name])
        np.savez(folder / f"{name}.npz", points_mm=pts, triangles=tri, layer=lay, lc_mm=BUILT[name])
    mesh.DATA = folder
    mesh.load_mesh.cache_clear()
    config.MESHES = SHIPPED + tuple(names)


def row(
    p,
    mesh: str,
    element: str,
    dt: float,
    sep_ratio: float | None = None,
    epithelium: tuple[float, float] | None = None,
    flow: str = "paper",
) -> list:
    from vfcore import SimConfig, simulate
    from vfcore.mesh import load_mesh

    t0 = time.perf_counter()
    extra = {} if sep_ratio is None else {"sep_ratio": sep_ratio}
    if epithelium is not None:
        extra.update(epithelium_E_kpa=epithelium[0], epithelium_h_mm=epithelium[1])
    r = simulate(
        p,
        SimConfig(mesh=mesh, dt=dt, duration=0.35, discard=0.15, element=element, contact="layer", flow=flow, **extra),
    )
    if not r.ok:
        return [
            mesh,
            load_mesh(mesh).n_triangles,
            element,
            dt,
            math.nan,
            math.nan,
            math.nan,
            math.nan,
            math.nan,
            math.nan,
            time.perf_counter() - t0,
        ]
    y = r.cycles
    closed = y is not None and y.period.size > 0
    cq = float(y.closed_quotient.mean()) if closed else 0.0
    imp = 1e3 * float(y.contact_impulse.mean()) if closed else 0.0
    pic = float(y.contact_pressure_in_contact.mean()) if closed else 0.0
    return [
        mesh,
        load_mesh(mesh).n_triangles,
        element,
        dt,
        r.f0,
        float(r.gaw.min()),
        float(r.gaw.max()),
        cq,
        imp,
        pic,
        time.perf_counter() - t0,
    ]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--elements", default="anp")
    ap.add_argument("--points", default="Table 3,A,B")
    ap.add_argument("--dt-check", action="store_true")
    ap.add_argument("--flow", default="paper", help="SimConfig.flow: the paper's node-wise load or the continuous one")
    ap.add_argument("--meshes", default=",".join(SHIPPED + ("x3fine",)))
    ap.add_argument(
        "--sep-ratio",
        type=float,
        default=None,
        help="flow separation at this multiple of the narrowest gap (default: SimConfig.sep_ratio's)",
    )
    ap.add_argument(
        "--epithelium",
        default=None,
        metavar="E_KPA,H_MM",
        help="add the epithelium membrane (SimConfig.epithelium_E_kpa, epithelium_h_mm; default none)",
    )
    a = ap.parse_args(argv)
    epi = None if a.epithelium is None else tuple(float(v) for v in a.epithelium.split(","))
    if epi is not None and len(epi) != 2:
        ap.error(f"--epithelium takes E_KPA,H_MM, got {a.epithelium!r}")
    np.seterr(all="ignore")
    from vfcore import TABLE3

    points = {
        "Table 3": TABLE3,
        "A": replace(TABLE3, E_cover=850.0, p_sub=800.0),
        "B": replace(TABLE3, E_cover=950.0, p_sub=1000.0),
        "C": replace(TABLE3, E_cover=500.0, p_sub=1200.0),
        "D": replace(TABLE3, E_cover=700.0, p_sub=1400.0),
    }
    with tempfile.TemporaryDirectory() as tmp:
        meshes = [m.strip() for m in a.meshes.split(",")]
        register_built(Path(tmp), [m for m in BUILT if m in meshes or (a.dt_check and m == "x3fine")])
        from vfcore import SimConfig

        print(
            f"flow {a.flow}, sep_ratio {SimConfig().sep_ratio if a.sep_ratio is None else a.sep_ratio:g}, epithelium "
            + ("none" if epi is None else f"{epi[0]:g} kPa, {epi[1]:g} mm")
        )
        print(
            "| point | mesh (triangles) | element | dt (s) | f0 (Hz) | min area (mm2) | max area (mm2) | CQ | "
            "impulse (mN s/m) | p in contact (Pa) | wall (s) |"
        )
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for name in a.points.split(","):
            p = points[name.strip()]
            for element in a.elements.split(","):
                runs = [(m, 5e-5) for m in meshes]
                if a.dt_check:
                    runs += [("xxfine", 2.5e-5), ("x3fine", 2.5e-5)]
                for mesh, dt in runs:
                    m, n, el, h, f0, lo, hi, cq, imp, pic, wall = row(p, mesh, element, dt, a.sep_ratio, epi, a.flow)
                    print(
                        f"| {name} | {m} ({n}) | {el} | {h:g} | {f0:.2f} | {lo:.2f} | {hi:.2f} | {cq:.3f} | "
                        f"{imp:.3f} | {pic:.1f} | {wall:.0f} |",
                        flush=True,
                    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
