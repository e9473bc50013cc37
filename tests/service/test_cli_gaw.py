"""`vfinfer gaw` on a synthetic stack of known GAW; bad input exits 2 with a message."""

from __future__ import annotations

import numpy as np
from typer.testing import CliRunner

from service.cli import app
from vfvideo.io import read_gaw
from vfvideo.synth import pulse_gaw, render_video


def test_cli_gaw_writes_csv_and_figure(tmp_path):
    fps, f0 = 2000.0, 125.0
    _, truth = pulse_gaw(fps, f0, 100, peak_mm2=4.0)
    vid = render_video(truth, fps, shape=(110, 120), center=(55.0, 60.0), length_mm=3.0, seed=5)
    src = tmp_path / "clip.npy"
    np.save(src, vid.frames)
    out = tmp_path / "gaw.csv"
    r = CliRunner().invoke(
        app, ["gaw", str(src), "--fps", "2000", "--px-per-mm", "24.4", "-o", str(out), "--segment-s", "0.04"]
    )
    assert r.exit_code == 0, r.output
    g = read_gaw(out)
    assert g.fps == fps and g.area.min() >= 0
    assert out.with_suffix(".png").exists()


def test_cli_gaw_bad_input(tmp_path):
    src = tmp_path / "flat.npy"
    np.save(src, np.full((30, 40, 40), 200, dtype=np.uint8))
    r = CliRunner().invoke(
        app, ["gaw", str(src), "--fps", "2000", "--px-per-mm", "24.4", "-o", str(tmp_path / "g.csv")]
    )
    assert r.exit_code == 2 and "error" in r.output
    assert not (tmp_path / "g.csv").exists()
