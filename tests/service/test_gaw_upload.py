"""Video upload: POST /gaw returns the GAW a job accepts; bad videos get a 422 naming the problem."""

from __future__ import annotations

import io

import numpy as np
from svc_helpers import auth

from vfvideo.synth import pulse_gaw, render_video


def _npy(frames: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, frames)
    return buf.getvalue()


def test_upload_recovers_known_gaw(service):
    fps, f0 = 2000.0, 125.0
    _, truth = pulse_gaw(fps, f0, 100, peak_mm2=4.0)
    vid = render_video(truth, fps, shape=(110, 120), center=(55.0, 60.0), length_mm=3.0, seed=3)
    r = service.http.post(
        "/gaw",
        headers=auth("alice"),
        files={"video": ("clip.npy", _npy(vid.frames))},
        data={"fps": str(fps), "px_per_mm": "24.4", "segment_s": "0.04"},
    )
    assert r.status_code == 200, r.text
    body = r.json()
    assert abs(body["f0_hz"] - f0) < 0.5
    a0, a1 = body["segment"]
    got = np.array(body["gaw"]["areas"])
    err = np.sqrt(np.mean((got - vid.area_mm2[a0:a1]) ** 2)) / vid.area_mm2.max()
    assert err < 0.05, err
    assert body["gaw"]["fps"] == fps and body["gaw"]["units"] == "mm2"


def test_upload_errors(service):
    h = auth("alice")
    static = np.full((40, 64, 64), 180, dtype=np.uint8)
    r = service.http.post(
        "/gaw", headers=h, files={"video": ("x.npy", _npy(static))}, data={"fps": "2000", "px_per_mm": "24.4"}
    )
    assert r.status_code == 422 and "video" in r.text
    r = service.http.post(
        "/gaw", headers=h, files={"video": ("x.npy", _npy(static))}, data={"fps": "0", "px_per_mm": "24.4"}
    )
    assert r.status_code == 422 and "fps" in r.text
    r = service.http.post(
        "/gaw", headers=h, files={"video": ("x.exe", b"MZ")}, data={"fps": "2000", "px_per_mm": "24.4"}
    )
    assert r.status_code == 422 and "unsupported" in r.text
    r = service.http.post(
        "/gaw", headers=h, files={"video": ("x.mp4", b"not a video")}, data={"fps": "2000", "px_per_mm": "24.4"}
    )
    assert r.status_code == 422
    r = service.http.post("/gaw", files={"video": ("x.npy", _npy(static))}, data={"fps": "2000", "px_per_mm": "24.4"})
    assert r.status_code == 401
