"""Window-continuation absorption search of the presence audit (benchmarks/concealed/absorb.py)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks.concealed import absorb as A  # noqa: E402
from benchmarks.concealed import generate as G  # noqa: E402
from vfcore import TABLE3, Params, simulate  # noqa: E402

CFG = G.BASE_CONFIG


def test_windows_double_from_the_first_cycles_to_the_whole_recording():
    assert A.windows(400, 15.0, 3.0) == [46, 92, 184, 368, 400]
    assert A.windows(400, 200.0, 3.0) == [400]  # fewer than 3 cycles: the whole window at once
    assert A.windows(400, float("nan"), 3.0) == [400]  # no f0: no continuation
    with pytest.raises(ValueError, match="at least 2 frames"):
        A.windows(1, 15.0, 3.0)


def test_bad_clean_waveform_is_refused():
    with pytest.raises(ValueError, match="finite 1-D waveform"):
        A.continued_unabsorbed_rms(np.array([1.0, np.nan, 2.0, 3.0, 4.0]), CFG, CFG.fps)


@pytest.mark.slow  # two continuation searches (about a minute on 2 cores)
def test_continuation_absorbs_a_base_waveform_from_an_exact_and_from_a_distant_start():
    """A waveform the base model produces exactly (at `hidden`) is fully absorbable: from a start
    at `hidden` the search returns it (the start is scored on the whole window, RMS ~ 0); from a
    start 20 % off in E_body (5 % off in f0: the 400-frame window, 13 cycles, drifts by 0.7 of a
    cycle) the continuation (3 cycles first, then doubling) brings the residual below 2 % of the
    waveform's amplitude."""
    hidden = {"E_body": 12.0, "E_cover": 600.0, "p_sub": 1000.0}
    r = simulate(Params(**{**TABLE3.as_dict(), **hidden}), CFG)
    assert r.ok
    clean = G.sample_hr(np.asarray(r.gaw_hr), G.hr_times(r), G.frame_times(G.N_OBS, 97.3, CFG.fps))
    amp = np.ptp(clean)
    u, fit, n_sim = A.continued_unabsorbed_rms(clean, CFG, CFG.fps, starts=[hidden], n_sobol=1, n_keep=0, maxfev=2)
    assert u < 1e-6 and fit == pytest.approx(hidden) and n_sim >= 2
    off = {**hidden, "E_body": 12.0 * 1.2}
    u_off, fit_off, n_off = A.continued_unabsorbed_rms(
        clean, CFG, CFG.fps, starts=[off], n_sobol=1, n_keep=0, maxfev=30
    )
    assert u_off < 0.02 * amp, (u_off, fit_off)
    assert n_off <= 2 + 2 * 5 * 31  # design + start, then two chains of 5 windows


def test_audit_both_stops_at_the_continuation_when_it_decides_and_refuses_unknown_methods(tmp_path):
    """`--audit-method both`: a waveform the base model reproduces at the generator's absorbing fit
    is decided (not present) by the continuation, so the design search is not run; audit.json
    records the method and which search gave the smallest misfit. An unknown method is refused
    before anything is written."""
    import json

    absorbing = {"E_body": 12.0, "E_cover": 600.0, "p_sub": 1000.0}
    r = simulate(Params(**{**TABLE3.as_dict(), **absorbing}), CFG)
    clean = G.sample_hr(np.asarray(r.gaw_hr), G.hr_times(r), G.frame_times(G.N_OBS, 97.3, CFG.fps))
    far = {**TABLE3.as_dict(), "E_body": 9.5, "E_cover": 900.0, "p_sub": 1700.0}
    hidden = {
        "seed": 0,
        "n_obs": G.N_OBS,
        "cases": {
            "00": {
                "label": "scale",
                "truth": far,
                "sigma_mm2": 0.5,
                "unabsorbed_rms_mm2": 3.0,
                "present": True,
                "absorbing_fit": absorbing,
                "clean": clean.tolist(),
            }
        },
    }
    (tmp_path / "truth.json").write_text(json.dumps(hidden))
    with pytest.raises(ValueError, match="method must be"):
        G.audit_presence(tmp_path, config=CFG, method="grid")
    assert not (tmp_path / "audit.json").exists()
    with pytest.raises(ValueError, match="method 'both' needs search"):  # a flat dict for two methods
        G.audit_presence(tmp_path, config=CFG, search={"n_sobol": 2, "maxfev": 4}, method="both")
    with pytest.raises(ValueError, match=r"unknown keys \['n_keep'\]"):  # a continuation key for the design
        G.audit_presence(tmp_path, config=CFG, search={"n_sobol": 2, "n_keep": 1}, method="design")
    assert not (tmp_path / "audit.json").exists()
    search = {
        "continuation": {"n_sobol": 1, "n_keep": 0, "maxfev": 2},
        "design": {"n_sobol": 2, "n_starts": 1, "maxfev": 4},
    }
    doc = G.audit_presence(tmp_path, config=CFG, search=search, method="both")
    c = doc["cases"]["00"]
    assert doc["method"] == "both" and c["smallest_from"] == "continuation"
    assert c["unabsorbed_rms_mm2"] < 1e-6 and not c["present"] and c["absorbing_fit"] == pytest.approx(absorbing)
