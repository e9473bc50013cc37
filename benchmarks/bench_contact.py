"""Contact products at Table 3 against the time step and the mesh, with observed orders.

Protocol: vfcore.params.TABLE3, SimConfig(duration=0.35, discard=0.15) (a dozen settled cycles of the
200 ms kept), default contact (exact multipliers, inelastic projection). Per quantity: the mean over the
kept cycles, except "max contact", the maximum over them. Observed order from three successive
refinements (ratio 2): p = log2(|q1 - q2| / |q2 - q3|), 'n/a' when the differences do not shrink;
"rel. diff." = |q(finest) - q(second finest)| / |q(finest)|.
Usage: OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_contact.py
"""
from __future__ import annotations

import math
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from vfcore import TABLE3, SimConfig, simulate  # noqa: E402
from vfcore.solver.system import get_system  # noqa: E402

DURATION, DISCARD = 0.35, 0.15
COLS = (("f0 (Hz)", "{:.2f}"), ("peak (mm2)", "{:.2f}"), ("CQ", "{:.3f}"), ("max contact (Pa)", "{:.0f}"),
        ("mean cycle max (Pa)", "{:.0f}"), ("impulse (mN s/m)", "{:.4f}"), ("p in contact (Pa)", "{:.1f}"),
        ("duration (ms)", "{:.3f}"))


def quantities(cfg: SimConfig) -> list[float]:
    r = simulate(TABLE3, cfg)
    y = r.cycles if r.ok else None
    if y is None or y.period.size == 0:
        return [math.nan] * len(COLS)
    return [r.f0, y.peak_area.mean(), y.closed_quotient.mean(), y.max_contact_pressure_unconverged.max(),
            y.max_contact_pressure_unconverged.mean(), 1e3 * y.contact_impulse.mean(),
            y.contact_pressure_in_contact.mean(), 1e3 * y.contact_duration.mean()]


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


def main() -> None:
    print(__doc__.split("Usage")[0])
    simulate(TABLE3, SimConfig(duration=0.01, discard=0.0))     # JIT warm-up
    dts = [1e-4, 5e-5, 2.5e-5, 1.25e-5]
    for element in ("p1", "anp"):
        rows = [quantities(SimConfig(dt=dt, duration=DURATION, discard=DISCARD, element=element)) for dt in dts]
        table([f"{dt:.3g}" for dt in dts], rows, f"dt (s), medium, {element}", True)
    labels, rows = [], []
    for element in ("p1", "anp"):
        for mesh in ("coarse", "medium", "fine"):
            n_tri = get_system(mesh, 0.4995, element).mesh.n_triangles
            labels.append(f"{mesh} ({n_tri}) {element}")
            rows.append(quantities(SimConfig(mesh=mesh, element=element, duration=DURATION, discard=DISCARD)))
    print("Meshes at dt 5e-5 (not nested; 'rel. diff.' compares the last two rows: medium and fine anp)")
    table(labels, rows, "mesh (triangles) element", False)


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
