"""The public high-speed clip of real vocal folds (../shared/data/hsv beside the repository)."""

from pathlib import Path

import numpy as np
import pytest

from vfvideo import extract_gaw, plot_extraction

REPO = Path(__file__).resolve().parents[2]
CLIP = REPO.parent / "shared" / "data" / "hsv" / "oscillating_vocal_folds.mp4"
FPS = 4000.0  # not stated in the source; typical of the recording system (see the data README)


@pytest.fixture(scope="module")
def ex():
    if not CLIP.is_file():
        pytest.fail(f"test clip missing: expected {CLIP} (the shared data folder ../shared beside the repository)")
    return extract_gaw(CLIP, fps=FPS, px_per_mm=24.4, fmax=1000.0)


def test_real_clip_periodic_nonnegative(ex):
    a = ex.area
    assert a.size == 47
    assert np.all(np.isfinite(a)) and np.all(a >= 0)
    assert a.max() > 0.5  # mm^2: a visible opening
    assert a.min() < 0.1 * a.max()  # (nearly) closes every cycle
    period = FPS / ex.f0
    assert 5.5 < period < 8.0  # about 6.7 frames per cycle
    lag = int(round(period))
    x = a - a.mean()
    r = [np.corrcoef(x[:-L], x[L:])[0, 1] for L in (lag - 1, lag, lag + 1)]
    assert max(r) > 0.8
    assert ex.measures["n_cycles"] >= 5
    assert np.mean(ex.ok) > 0.9


def test_real_clip_contour_and_figure(ex, tmp_path):
    r0, r1, c0, c1 = ex.seg.roi
    # the glottis lies in the left-centre part of the 448x448 frame (checked by eye)
    assert 60 < c0 < c1 < 220 and 80 < r0 < r1 < 320
    # the opening is elongated along the glottal axis (length > 4 x width)
    i = int(np.argmax(ex.area))
    rows = np.flatnonzero(ex.seg.masks[i].any(1))
    widths = ex.seg.right_edge[i] - ex.seg.left_edge[i]
    assert rows.size > 4 * np.nanmax(widths)
    plot_extraction(ex, tmp_path / "real.png")
    assert (tmp_path / "real.png").stat().st_size > 10_000
