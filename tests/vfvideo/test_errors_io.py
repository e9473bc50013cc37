"""Bad input gives a clear error, never a silent zero waveform; GAW file reading."""

import numpy as np
import pytest

from vfvideo import GawFileError, VideoError, extract_gaw, read_frames, read_gaw, write_gaw_csv
from vfvideo.synth import pulse_gaw, render_video


def small_video(n=40, **kw):
    _, a = pulse_gaw(2000.0, 200.0, n, peak_mm2=1.5)
    return render_video(a, 2000.0, px_per_mm=24.4, shape=(160, 140), center=(80.0, 70.0), length_mm=4.0, **kw)


def test_unreadable_file(tmp_path):
    p = tmp_path / "broken.mp4"
    p.write_bytes(b"this is not a video" * 50)
    with pytest.raises(VideoError, match="cannot read"):
        extract_gaw(p, fps=2000, px_per_mm=24.4)
    with pytest.raises(VideoError, match="no such file"):
        extract_gaw(tmp_path / "missing.mp4", fps=2000, px_per_mm=24.4)
    empty = tmp_path / "empty.avi"
    empty.write_bytes(b"")
    with pytest.raises(VideoError, match="empty"):
        read_frames(empty)


def test_zero_frames(tmp_path):
    with pytest.raises(VideoError, match="no frames"):
        read_frames(tmp_path)  # empty folder
    np.save(tmp_path / "none.npy", np.zeros((0, 20, 20), np.uint8))
    with pytest.raises(VideoError, match="no frames"):
        extract_gaw(tmp_path / "none.npy", fps=2000, px_per_mm=24.4)


@pytest.mark.parametrize("fps", [0, -2000, float("nan"), "fast"])
def test_bad_frame_rate(fps):
    with pytest.raises(ValueError, match="fps must be"):
        extract_gaw(np.zeros((5, 10, 10)), fps=fps, px_per_mm=24.4)


def test_bad_pixel_size():
    with pytest.raises(ValueError, match="px_per_mm must be"):
        extract_gaw(np.zeros((5, 10, 10)), fps=2000, px_per_mm=0)


def test_frames_of_different_sizes(tmp_path):
    import imageio.v3 as iio

    iio.imwrite(tmp_path / "f001.png", np.full((40, 50), 100, np.uint8))
    iio.imwrite(tmp_path / "f002.png", np.full((40, 52), 100, np.uint8))
    with pytest.raises(VideoError, match="different sizes"):
        extract_gaw(tmp_path, fps=2000, px_per_mm=24.4)


def test_no_visible_opening_static():
    v = small_video()
    static = np.repeat(v.frames[:1], 40, axis=0).astype(float)
    static += np.random.default_rng(0).normal(0, 3, static.shape)  # sensor noise only
    with pytest.raises(VideoError, match="no visible opening"):
        extract_gaw(static, fps=2000, px_per_mm=24.4)


def test_no_visible_opening_closed_glottis():
    _, a = pulse_gaw(2000.0, 200.0, 40, peak_mm2=1.5)
    v = render_video(np.zeros(40), 2000.0, shape=(160, 140), center=(80.0, 70.0), length_mm=4.0)
    with pytest.raises(VideoError, match="no visible opening"):
        extract_gaw(v.frames, fps=2000, px_per_mm=24.4)


def test_bright_flicker_is_not_an_opening():
    v = small_video()
    f = v.frames.astype(float)
    yy, xx = np.mgrid[0:160, 0:140]
    blob = np.exp(-((yy - 40) ** 2 + (xx - 100) ** 2) / 50.0)
    f = np.repeat(np.full((1, 160, 140), 120.0), 40, axis=0)
    f += 80 * blob[None] * (1 + np.sin(np.arange(40) / 3.0))[:, None, None]  # a bright moving reflection
    with pytest.raises(VideoError, match="no visible opening"):
        extract_gaw(f, fps=2000, px_per_mm=24.4)


def test_folder_and_npy_stacks(tmp_path):
    import imageio.v3 as iio

    v = small_video()
    d = tmp_path / "frames"
    d.mkdir()
    for i, fr in enumerate(v.frames):
        iio.imwrite(d / f"img{i}.png", fr)  # natural sort: img2 before img10
    np.save(tmp_path / "stack.npy", v.frames)
    a = extract_gaw(d, fps=2000, px_per_mm=24.4).area
    b = extract_gaw(tmp_path / "stack.npy", fps=2000, px_per_mm=24.4).area
    np.testing.assert_array_equal(a, b)
    assert np.all(a >= 0) and a.max() > 0.5


def test_video_file_roundtrip(tmp_path):
    import imageio.v3 as iio

    v = small_video(n=60)
    p = tmp_path / "clip.mp4"
    iio.imwrite(
        p,
        np.ascontiguousarray(v.frames[..., None].repeat(3, -1)),
        fps=25,
        codec="libx264",
        quality=10,
        macro_block_size=4,
    )
    ex = extract_gaw(p, fps=2000, px_per_mm=24.4)
    assert ex.area.size == 60
    err = np.sqrt(np.mean((ex.area - v.area_mm2) ** 2)) / v.area_mm2.max()
    assert err < 0.06  # lossy codec on a tiny glottis
    assert ex.f0 == pytest.approx(200.0, abs=0.5)


def test_read_gaw_formats(tmp_path):
    fps = 2000.0
    t = np.arange(50) / fps
    area = 1 + np.sin(2 * np.pi * 100 * t)
    # written file
    p = write_gaw_csv(tmp_path / "g.csv", t, area, fps, meta={"source": "x"})
    g = read_gaw(p)
    np.testing.assert_allclose(g.area, area, rtol=1e-8)
    assert g.fps == fps and g.meta["source"] == "x"
    # foreign CSV: ms and pixels
    q = tmp_path / "px.csv"
    q.write_text("time_ms,area_px\n" + "\n".join(f"{ti * 1e3},{ai * 24.4**2}" for ti, ai in zip(t, area)))
    with pytest.raises(GawFileError, match="px_per_mm"):
        read_gaw(q)
    g = read_gaw(q, px_per_mm=24.4)
    np.testing.assert_allclose(g.area, area, rtol=1e-9)
    assert g.fps == pytest.approx(fps)
    # single column needs fps; unit override
    r = tmp_path / "one.csv"
    r.write_text("\n".join(str(a / 100) for a in area))
    with pytest.raises(GawFileError, match="fps"):
        read_gaw(r)
    np.testing.assert_allclose(read_gaw(r, fps=fps, area_unit="cm^2").area, area, rtol=1e-9)
    # npy
    np.save(tmp_path / "a.npy", area)
    assert read_gaw(tmp_path / "a.npy", fps=fps).area.size == 50
    np.save(tmp_path / "ta.npy", np.column_stack([t, area]))
    assert read_gaw(tmp_path / "ta.npy").fps == pytest.approx(fps)
    # bad files
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,area_mm2\n0,1\n0.001,2\n0.0025,1\n")
    with pytest.raises(GawFileError, match="non-uniform"):
        read_gaw(bad)
    bad.write_text("time_s,area_mm2\n0,1\n0.001,-2\n")
    with pytest.raises(GawFileError, match="negative"):
        read_gaw(bad)
    with pytest.raises(GawFileError, match="fps"):
        read_gaw(p, fps=0.0 + 1000.0)  # disagrees with the time column
