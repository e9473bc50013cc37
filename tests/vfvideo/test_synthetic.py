"""Synthetic videos rendered from a known GAW: the segmentation must recover it."""

import numpy as np
import pytest

from vfcore.measures import estimate_f0
from vfvideo import extract_gaw, plot_extraction, read_gaw
from vfvideo.synth import pulse_gaw, render_video

FPS = 2000.0
PX = 24.4

CASES = {
    # name: (f0, n_frames, render kwargs, gaw kwargs)
    "paper_frame_asym": (
        125.0,
        160,
        dict(
            center=(200.0, 300.0), tilt=0.15, asymmetry=0.2, blur_sigma=1.2, noise_sigma=4.0, illumination=0.5, seed=1
        ),
        dict(peak_mm2=8.0),
    ),
    "gap_strong_light": (
        137.0,
        140,
        dict(
            center=(290.0, 170.0),
            length_mm=10.0,
            tilt=-0.1,
            blur_sigma=1.3,
            noise_sigma=6.0,
            illumination=0.7,
            chink_mm2=0.6,
            seed=2,
        ),
        dict(peak_mm2=6.0, gap_mm2=0.6, open_quotient=0.8, speed_quotient=1.5),
    ),
}


@pytest.fixture(scope="module", params=sorted(CASES))
def case(request):
    f0, n, rk, gk = CASES[request.param]
    _, area = pulse_gaw(FPS, f0, n, **gk)
    video = render_video(area, FPS, px_per_mm=PX, **rk)
    ex = extract_gaw(video.frames, fps=FPS, px_per_mm=PX, segment_s=0.05)
    return f0, video, ex


def test_gaw_within_3_percent_of_peak(case):
    _, video, ex = case
    err = np.sqrt(np.mean((ex.area - video.area_mm2) ** 2)) / video.area_mm2.max()
    assert err < 0.03, f"RMS error {err:.4f} of peak area"
    assert np.all(ex.ok)


def test_f0_exact(case):
    f0, video, ex = case
    # the known f0 (not just the estimate of the known GAW) within 0.02 Hz
    assert estimate_f0(ex.area, FPS) == pytest.approx(f0, abs=0.02)
    assert estimate_f0(ex.area, FPS) == pytest.approx(estimate_f0(video.area_mm2, FPS), abs=0.02)
    assert ex.measures["f0_hz"] == pytest.approx(ex.f0)


def test_roi_is_found_off_centre(case):
    _, video, ex = case
    r0, r1, c0, c1 = ex.seg.roi
    h, w = video.frames.shape[1:]
    cy, cx = video.center
    assert r0 <= cy <= r1 and c0 <= cx <= c1
    assert (r1 - r0) * (c1 - c0) < 0.35 * h * w


def test_left_right_areas(case):
    _, video, ex = case
    np.testing.assert_allclose(ex.area_left + ex.area_right, ex.area, rtol=1e-12, atol=1e-12)
    true_frac = video.area_left_mm2.sum() / video.area_mm2.sum()
    assert ex.area_left.sum() / ex.area.sum() == pytest.approx(true_frac, abs=0.03)


def test_csv_roundtrip_and_figure(case, tmp_path):
    _, _, ex = case
    p = ex.write_csv(tmp_path / "gaw.csv")
    g = read_gaw(p)
    assert g.fps == FPS
    np.testing.assert_allclose(g.area, ex.segment_area, rtol=1e-8)
    np.testing.assert_allclose(g.t, ex.segment_t, atol=1e-9)
    full = read_gaw(ex.write_csv(tmp_path / "full.csv", full=True))
    assert full.area.size == ex.area.size
    plot_extraction(ex, tmp_path / "fig.png")
    assert (tmp_path / "fig.png").stat().st_size > 10_000
