"""Figures of the forward model: the layered mesh (paper Fig. 2), deformed shapes over
one cycle (Fig. 3) and the GAW. matplotlib is imported lazily (Agg backend)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .config import SimConfig
from .forward import midline, simulate
from .mesh import LAYER_NAMES, load_mesh
from .params import TABLE3, Params

LAYER_COLOURS = ("#c9a27e", "#6f9fd8", "#e07a7a")


def plot_model(
    params: Params = TABLE3, config: SimConfig | None = None, path: str | Path | None = None, n_shapes: int = 6
):
    """Three panels: mesh coloured by layer, deformed shapes at ``n_shapes`` instants of
    the last full cycle, and the GAW (mm^2) with those instants marked.

    Returns the matplotlib Figure (saved to ``path`` when given).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    config = (config or SimConfig()).replace(keep_trajectories=True)
    res = simulate(params, config)
    if not res.ok:
        raise RuntimeError(f"simulation failed: {res.message}")
    mesh = load_mesh(config.mesh)
    p_mm = mesh.points * 1e3
    fig, axes = plt.subplots(1, 3, figsize=(15, 5.2), gridspec_kw={"width_ratios": [1, 1, 1.6]})
    ax = axes[0]
    for k, name in enumerate(LAYER_NAMES):
        tri = mesh.triangles[mesh.layer == k]
        ax.add_collection(
            PolyCollection(
                p_mm[tri], facecolors=LAYER_COLOURS[k], edgecolors="k", linewidths=0.4, label=f"{name} ({len(tri)})"
            )
        )
    ax.plot(p_mm[mesh.fixed, 0], p_mm[mesh.fixed, 1], "ks", ms=3, label="fixed nodes")
    ax.axvline(midline(params, config) * 1e3, color="0.4", ls="--", lw=1, label="midline")
    ax.set(
        xlim=(-0.5, 9.2),
        ylim=(-0.5, 11.2),
        aspect="equal",
        xlabel="x (mm, medial →)",
        ylabel="z (mm, superior ↑)",
        title=f"mesh '{config.mesh}': {mesh.n_triangles} triangles, {mesh.n_nodes} nodes",
    )
    ax.legend(fontsize=7, loc="lower left")

    cyc = res.cycles
    t0 = cyc.t_start[-1] if cyc is not None and cyc.t_start.size else res.t[0]
    T = cyc.period[-1] if cyc is not None and cyc.period.size else 0.01
    inst = t0 + T * np.arange(n_shapes) / n_shapes
    frames = np.clip(np.searchsorted(res.t, inst), 0, len(res.t) - 1)
    ax = axes[1]
    cmap = plt.get_cmap("viridis")
    surf = mesh.surface
    for i, f in enumerate(frames):
        q = p_mm + res.trajectories[f]
        ax.plot(
            q[surf, 0],
            q[surf, 1],
            color=cmap(i / max(1, n_shapes - 1)),
            lw=1.5,
            label=f"t = {1e3 * (res.t[f] - res.t[frames[0]]):.1f} ms",
        )
    ax.plot(p_mm[surf, 0], p_mm[surf, 1], "k:", lw=1, label="undeformed")
    ax.axvline(midline(params, config) * 1e3, color="0.4", ls="--", lw=1)
    ax.set(
        xlim=(2, 9.2),
        ylim=(-0.5, 16),
        aspect="equal",
        xlabel="x (mm)",
        ylabel="z (mm)",
        title="free surface over one cycle",
    )
    ax.legend(fontsize=7, loc="upper left")

    ax = axes[2]
    ax.plot(1e3 * res.t, res.gaw, "k-", lw=1)
    ax.plot(1e3 * res.t[frames], res.gaw[frames], "o", color="C3", ms=4)
    ax.set(
        xlabel="time after transient (ms)",
        ylabel="glottal area (mm²)",
        title=f"GAW at {config.fps:.0f} fps: f0 = {res.f0:.1f} Hz, peak = {res.gaw.max():.1f} mm²",
    )
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=130)
    return fig


if __name__ == "__main__":  # python -m vfcore.figures out.png
    import sys

    plot_model(path=sys.argv[1] if len(sys.argv) > 1 else "model.png")
