"""The real clip's path before a fit (benchmarks/real_example.py): video -> GAW -> the reach of the human prior
set, at the assumed 1000 fps and the system's typical 4000 fps, calibrated and with the area scale unknown."""

from __future__ import annotations

import pytest

from benchmarks import real_example as rx

pytestmark = pytest.mark.skipif(not rx.CLIP.is_file(), reason=f"the shared clip is absent: {rx.CLIP}")


def test_video_to_gaw_to_reach_on_the_real_clip():
    ex = rx.extract(rx.CLIP, 1000.0)
    assert ex.area.size == 47 and 140.0 < ex.f0 < 155.0  # 6.7 frames per cycle at 1000 fps
    v = {(r["fps"], r["area_scale"] is not None): r for r in rx.reach_verdicts(ex.area, [1000.0, 4000.0])}
    # 4000 fps: f0 ~594 Hz, beyond every draw of the human set, whatever the area scale
    for unknown in (False, True):
        r = v[(4000.0, unknown)]
        assert r["verdict"] == "outside" and "recording f0 594 Hz" in r["message"] and "--fps" in r["message"]
    # 1000 fps: f0 148 Hz is human; the nominal 1.86 mm^2 peak lies below the set's 5 % (marginal), an unknown
    # scale on [0.25, 4] lets it stand for 0.47-7.4 mm^2, inside the reach
    assert v[(1000.0, False)]["verdict"] == "marginal" and "peak area 1.86 mm^2" in v[(1000.0, False)]["message"]
    assert v[(1000.0, True)]["verdict"] == "inside"
