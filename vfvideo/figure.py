"""Figure of an extraction: a few frames with the contour overlaid, and the GAW."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["plot_extraction"]


def plot_extraction(ex, path=None):
    """Draw ``ex`` (a :class:`vfvideo.GawExtraction`): thumbnails of one cycle with the
    segmented contour (red), edges and glottal axis, and the GAW with the selected
    segment shaded and flagged frames marked. Saves to ``path`` if given; returns the
    matplotlib Figure."""
    import matplotlib

    if path is not None:
        matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from skimage import measure

    k = len(ex.thumbs)
    fig = plt.figure(figsize=(3.0 * max(k, 3), 6.5))
    gs = fig.add_gridspec(2, max(k, 1), height_ratios=[1.4, 1.0])
    r0, r1, c0, c1 = ex.seg.roi
    a_ax, b_ax = ex.seg.axis
    for j, (i, img, mask) in enumerate(ex.thumbs):
        ax = fig.add_subplot(gs[0, j])
        ax.imshow(img, cmap="gray", extent=(c0 - 0.5, c1 - 0.5, r1 - 0.5, r0 - 0.5))
        for cnt in measure.find_contours(mask.astype(float), 0.5):
            ax.plot(cnt[:, 1] + c0, cnt[:, 0] + r0, "r-", lw=0.8)
        rows = np.array([r0, r1 - 1])
        ax.plot(a_ax + b_ax * (rows + 0.5) - 0.5, rows, "c--", lw=0.6)
        ax.set_title(f"frame {i}: {ex.area[i]:.2f} mm$^2$", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    ax = fig.add_subplot(gs[1, :])
    t_ms = ex.t * 1e3
    ax.plot(t_ms, ex.area, "k-", lw=1, label="GAW")
    ax.plot(t_ms, ex.area_left, "b-", lw=0.6, alpha=0.7, label="left of axis")
    ax.plot(t_ms, ex.area_right, "g-", lw=0.6, alpha=0.7, label="right of axis")
    bad = ~ex.ok
    if bad.any():
        ax.plot(t_ms[bad], ex.area[bad], "rx", ms=4, label="flagged")
    a, b = ex.segment
    ax.axvspan(t_ms[a], t_ms[b - 1], color="orange", alpha=0.15, label="segment")
    ax.set_xlabel("time (ms)")
    ax.set_ylabel("area (mm$^2$)")
    ax.set_title(f"f0 = {ex.f0:.1f} Hz at {ex.fps:g} fps, {ex.px_per_mm:g} px/mm", fontsize=10)
    ax.legend(fontsize=7, loc="upper right", ncol=3)
    fig.tight_layout()
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return fig
