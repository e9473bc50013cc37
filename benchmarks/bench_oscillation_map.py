"""Where each mesh self-oscillates: p_sub x E_cover map at the other Table 3 values.

For each mesh (coarse, medium, fine) at dt = 5e-5 s, 550 ms simulated, the last 300 ms kept,
every grid point is classified from the kept camera-rate GAW:

  O  oscillating   peak-to-peak of the last 100 ms > 0.5 mm^2 and a finite f0 (vfcore.measures.estimate_f0)
  i  irregular     peak-to-peak of the last 100 ms > 0.5 mm^2 but no f0 (aperiodic motion)
  .  steady open   peak-to-peak <= 0.5 mm^2, minimum area of the last 100 ms > 0
  c  closed        peak-to-peak <= 0.5 mm^2, the glottis stays closed
  x  failed        the run diverged (displacement > 1 cm or non-finite)

Prints a text map per mesh (rows p_sub, columns E_cover) and the f0 (Hz) / mean cycle peak area
(mm^2) at the oscillating points; saves docs/img/oscillation_map[_<element>].png.

Usage: OMP_NUM_THREADS=1 python benchmarks/bench_oscillation_map.py [--element p1|anp] [--no-figure]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from vfcore import TABLE3, SimConfig, simulate  # noqa: E402
from vfcore.config import ELEMENTS, MESHES  # noqa: E402
from vfcore.measures import cycle_boundaries, estimate_f0  # noqa: E402

P_SUB = np.linspace(400.0, 1800.0, 8)  # Pa
E_COVER = np.linspace(250.0, 950.0, 8)  # Pa
P2P_MIN = 0.5  # mm^2
LAST = 0.1  # s
HEAD = "p_sub \\ E_cover"
SYMBOL = {"osc": "O", "irregular": "i", "open": ".", "closed": "c", "failed": "x"}
IMG = Path(__file__).resolve().parents[1] / "docs" / "img"


def peak_area(gaw: np.ndarray, fps: float, f0: float) -> float:
    """Mean over cycles (minimum to minimum at the autocorrelation f0) of the cycle maximum, mm^2."""
    b = cycle_boundaries(gaw, fps, f0)
    if b.size < 2:
        return float(gaw.max())
    return float(np.mean([gaw[i : j + 1].max() for i, j in zip(b[:-1], b[1:])]))


def classify(r) -> tuple[str, float, float]:
    """(class, f0 Hz, mean cycle peak area mm^2) of one SimResult."""
    if not r.ok:
        return "failed", float("nan"), float("nan")
    n_last = int(round(LAST * r.fps))
    last = r.gaw[-n_last:]
    f0 = estimate_f0(r.gaw, r.fps)
    if np.ptp(last) > P2P_MIN:
        if np.isfinite(f0):
            return "osc", f0, peak_area(r.gaw, r.fps, f0)
        return "irregular", float("nan"), float("nan")
    return ("open" if last.min() > 0.0 else "closed"), float("nan"), float("nan")


def run_map(mesh: str, element: str, dt: float = 5e-5):
    cfg = SimConfig(mesh=mesh, dt=dt, element=element)
    cls = np.empty((P_SUB.size, E_COVER.size), dtype=object)
    f0 = np.full(cls.shape, np.nan)
    pk = np.full(cls.shape, np.nan)
    for i, ps in enumerate(P_SUB):
        for j, ec in enumerate(E_COVER):
            cls[i, j], f0[i, j], pk[i, j] = classify(simulate(TABLE3.replace(p_sub=ps, E_cover=ec), cfg))
    return cls, f0, pk


def print_map(mesh: str, element: str, cls, f0, pk) -> None:
    n_osc = int(np.sum(cls == "osc"))
    print(
        f"\nmesh {mesh}, element {element}: {n_osc}/{cls.size} oscillating   "
        f"(O oscillating, i irregular, . steady open, c closed, x failed)"
    )
    print(f"{HEAD:>16s} " + " ".join(f"{e:6.0f}" for e in E_COVER))
    for i, ps in enumerate(P_SUB):
        print(f"{ps:16.0f} " + " ".join(f"{SYMBOL[c]:>6s}" for c in cls[i]))
    print("f0 (Hz) / mean peak area (mm^2) at oscillating points:")
    print(f"{HEAD:>16s} " + " ".join(f"{e:>11.0f}" for e in E_COVER))
    for i, ps in enumerate(P_SUB):
        cells = [
            f"{f0[i, j]:5.1f}/{pk[i, j]:5.1f}" if cls[i, j] == "osc" else f"{SYMBOL[cls[i, j]]:>11s}"
            for j in range(E_COVER.size)
        ]
        print(f"{ps:16.0f} " + " ".join(cells))


def agreement(results) -> None:
    """Cross-mesh agreement: same class everywhere, and f0 / peak spread where all meshes oscillate."""
    cls = np.stack([r[0] for r in results.values()])
    f0 = np.stack([r[1] for r in results.values()])
    pk = np.stack([r[2] for r in results.values()])
    same = np.all(cls == cls[0], axis=0)
    osc = np.all(cls == "osc", axis=0)
    print(
        f"\ncross-mesh ({', '.join(results)}): same class at {same.sum()}/{same.size} points; "
        f"all oscillate at {osc.sum()} points"
    )
    if osc.any():
        for name, q in (("f0", f0), ("peak", pk)):
            spread = (q.max(axis=0) - q.min(axis=0))[osc] / q.mean(axis=0)[osc]
            print(
                f"  {name} spread (max - min) / mean over meshes at those points: median {np.median(spread):.3f}, "
                f"max {spread.max():.3f}"
            )


def figure(results, element: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(4.2 * len(results), 4.0), sharey=True, constrained_layout=True)
    de, dp = E_COVER[1] - E_COVER[0], P_SUB[1] - P_SUB[0]
    ext = (E_COVER[0] - de / 2, E_COVER[-1] + de / 2, P_SUB[0] - dp / 2, P_SUB[-1] + dp / 2)
    im = None
    for ax, (mesh, (cls, f0, pk)) in zip(axes, results.items()):
        im = ax.imshow(
            np.where(cls == "osc", pk, np.nan),
            origin="lower",
            extent=ext,
            aspect="auto",
            cmap="viridis",
            vmin=0,
            vmax=60,
        )
        for i, ps in enumerate(P_SUB):
            for j, ec in enumerate(E_COVER):
                txt = f"{f0[i, j]:.0f}" if cls[i, j] == "osc" else SYMBOL[cls[i, j]]
                ax.text(ec, ps, txt, ha="center", va="center", fontsize=7, color="w" if cls[i, j] == "osc" else "k")
        ax.plot(TABLE3.E_cover, TABLE3.p_sub, "r+", ms=12, mew=2)
        ax.set_title(f"{mesh} ({int(np.sum(cls == 'osc'))}/{cls.size} osc.)")
        ax.set_xlabel("E_cover (Pa)")
    axes[0].set_ylabel("p_sub (Pa)")
    fig.colorbar(im, ax=axes, label="mean peak area (mm$^2$)")
    fig.suptitle(
        f"Self-oscillation, Table 3 except p_sub, E_cover (element {element}, dt 0.05 ms). "
        "Text: f0 (Hz); i irregular, '.' steady open, c closed, x failed; + Table 3",
        fontsize=10,
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"\nfigure: {path}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--element", default="p1", choices=ELEMENTS)
    ap.add_argument("--meshes", default=",".join(MESHES))
    ap.add_argument("--no-figure", action="store_true")
    a = ap.parse_args()
    simulate(TABLE3, SimConfig(duration=0.01, discard=0.0))  # JIT warm-up
    results = {}
    for mesh in a.meshes.split(","):
        t0 = time.perf_counter()
        results[mesh] = run_map(mesh, a.element)
        print_map(mesh, a.element, *results[mesh])
        print(f"({P_SUB.size * E_COVER.size} simulations in {time.perf_counter() - t0:.1f} s)")
    if len(results) > 1:
        agreement(results)
    if not a.no_figure:
        name = "oscillation_map.png" if a.element == "p1" else f"oscillation_map_{a.element}.png"
        figure(results, a.element, IMG / name)


if __name__ == "__main__":
    main()
