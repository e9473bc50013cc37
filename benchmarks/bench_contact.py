"""Contact products against the time step and the mesh, with observed orders, for both contact laws.

Protocol: SimConfig(duration=0.35, discard=0.15) (a dozen settled cycles of the 200 ms kept), at
vfcore.params.TABLE3 and at three prior draws that close (rows of the shipped coarse reach ensemble,
vfcore/data/reach_1f8e3fcc3b22aa3c.csv, at the quartiles of E_cover among the draws that phonate with an
open quotient below 0.95). Contact laws: "projection" (the paper's exact multipliers and inelastic
impact) and "layer" (the compliant Kelvin-Voigt layer, 0.1 mm). Per quantity: the mean over the
kept cycles, except "max contact", the maximum over them. Observed order from three successive
refinements (ratio 2): p = log2(|q1 - q2| / |q2 - q3|), 'n/a' when the differences do not shrink;
"rel. diff." = |q(finest) - q(second finest)| / |q(finest)|.
Usage: OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_contact.py [--draws]
"""

from __future__ import annotations

import math
import os
import sys

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from vfcore import TABLE3, Params, SimConfig, simulate  # noqa: E402
from vfcore.solver.system import get_system  # noqa: E402

DURATION, DISCARD = 0.35, 0.15
COLS = (
    ("f0 (Hz)", "{:.2f}"),
    ("peak (mm2)", "{:.2f}"),
    ("CQ", "{:.3f}"),
    ("max contact (Pa)", "{:.0f}"),
    ("mean cycle max (Pa)", "{:.0f}"),
    ("impulse (mN s/m)", "{:.4f}"),
    ("p in contact (Pa)", "{:.1f}"),
    ("duration (ms)", "{:.3f}"),
)


#: prior draws that close (see the protocol above), paper units in PARAM_NAMES order
DRAWS = {
    "draw A": Params(10.347786, 532.031253, 1.128750, 1033.615735, 1176.533458, 1.544419, 8.125851),
    "draw B": Params(9.220915, 702.825886, 2.778783, 1412.358740, 1127.321926, 4.314788, 8.115661),
    "draw C": Params(14.375210, 839.293579, 2.096306, 1378.564039, 979.066690, 1.752197, 8.305795),
}
MESHES = ("coarse", "medium", "fine", "xfine", "xxfine")
DTS = [1e-4, 5e-5, 2.5e-5, 1.25e-5, 6.25e-6]


def quantities(cfg: SimConfig, p: Params = TABLE3) -> list[float]:
    r = simulate(p, cfg)
    y = r.cycles if r.ok else None
    if y is None or y.period.size == 0:
        return [math.nan] * len(COLS)
    return [
        r.f0,
        y.peak_area.mean(),
        y.closed_quotient.mean(),
        y.max_contact_pressure_unconverged.max(),
        y.max_contact_pressure_unconverged.mean(),
        1e3 * y.contact_impulse.mean(),
        y.contact_pressure_in_contact.mean(),
        1e3 * y.contact_duration.mean(),
    ]


def orders(q: list[float]) -> str:
    out = []
    for a, b, c in zip(q[:-2], q[1:-1], q[2:]):
        d1, d2 = abs(a - b), abs(b - c)
        out.append(f"{math.log2(d1 / d2):.2f}" if d2 > 0 and d1 > d2 else "n/a")
    return ", ".join(out)


def table(labels: list[str], rows: list[list[float]], head: str, with_orders: bool) -> None:
    print(f"| {head} | " + " | ".join(c for c, _ in COLS) + " |")
    print("|" + "---|" * (len(COLS) + 1))
    for lab, row in zip(labels, rows):
        print(f"| {lab} | " + " | ".join(fmt.format(x) for (_, fmt), x in zip(COLS, row)) + " |")
    cols = list(zip(*rows))
    if with_orders:
        print("| observed order | " + " | ".join(orders(list(c)) for c in cols) + " |")
    print("| rel. diff. two finest | " + " | ".join(f"{abs(c[-1] - c[-2]) / abs(c[-1]):.1%}" for c in cols) + " |")
    print()


def dt_table(p: Params, name: str, contact: str, element: str) -> None:
    rows = [
        quantities(SimConfig(dt=dt, duration=DURATION, discard=DISCARD, element=element, contact=contact), p)
        for dt in DTS
    ]
    table([f"{dt:.3g}" for dt in DTS], rows, f"{name}: dt (s), medium, {element}, {contact}", True)


def mesh_table(p: Params, name: str, contact: str, dt: float = 5e-5) -> None:
    labels, rows = [], []
    for element in ("p1", "anp"):
        for mesh in MESHES:
            n_tri = get_system(mesh, 0.4995, element).mesh.n_triangles
            labels.append(f"{mesh} ({n_tri}) {element}")
            rows.append(
                quantities(
                    SimConfig(mesh=mesh, element=element, dt=dt, duration=DURATION, discard=DISCARD, contact=contact), p
                )
            )
    print(
        f"{name}, {contact}: meshes at dt {dt:g} (not nested; 'rel. diff.' compares the last two rows: "
        "xfine and xxfine anp)"
    )
    table(labels, rows, "mesh (triangles) element", False)


def main(draws: bool) -> None:
    print(__doc__.split("Usage")[0])
    simulate(TABLE3, SimConfig(duration=0.01, discard=0.0))  # JIT warm-up
    for contact in ("projection", "layer"):
        for element in ("p1", "anp"):
            dt_table(TABLE3, "Table 3", contact, element)
        mesh_table(TABLE3, "Table 3", contact)
    if draws:
        for name, p in DRAWS.items():
            dt_table(p, name, "layer", "p1")
            mesh_table(p, name, "layer")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main("--draws" in sys.argv[1:])
