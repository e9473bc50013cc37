"""Sub-frame, profile-likelihood alignment (vfcore.observe.align) and the continuity it buys."""

import dataclasses

import numpy as np
import pytest

from vfcore.config import SimConfig
from vfcore.forward import simulate
from vfcore.observe import align, alignment_window
from vfcore.params import TABLE3
from vfcore.result import HR_OVERSAMPLE

FPS = 2000.0


def _signal(q=HR_OVERSAMPLE, n=600, f0=63.7):
    t = np.arange(q * (n - 1) + 1) / (q * FPS)
    # a GAW-like pulse train: half-wave rectified, sharpened sine (closed phase at zero)
    return 20.0 * np.maximum(np.sin(2 * np.pi * f0 * t), 0.0) ** 1.5


@pytest.mark.parametrize("shift", [7.0, 7.3, 12.55, 20.91])
@pytest.mark.parametrize("method", ["profile", "xcorr"])
def test_fractional_shift_is_recovered(shift, method):
    hr = _signal()
    sim = hr[::HR_OVERSAMPLE]
    t_fine = np.arange(hr.size) / HR_OVERSAMPLE
    obs = np.interp(shift + np.arange(300), t_fine, hr)  # the recording starts `shift` frames in
    seg, o, lag = align(sim, obs, FPS, (40, 300), sim_hr=hr, oversample=HR_OVERSAMPLE, method=method)
    # the right cycle modulo one period (31.4 frames at 63.7 Hz)
    period = FPS / 63.7
    d = (lag - shift + period / 2) % period - period / 2
    assert abs(d) < 0.05  # a twentieth of a frame (25 us at 2000 fps)
    if method == "profile":
        assert np.sqrt(np.mean((seg - obs) ** 2)) < 0.02 * obs.max()
    # the integer path can only be right to within half a frame
    _, _, lag_int = align(sim, obs, FPS, (40, 300), method=method)
    assert float(lag_int).is_integer()


def test_bad_oversampled_input_is_rejected():
    hr = _signal()
    with pytest.raises(ValueError, match="sim_hr"):
        align(hr[::HR_OVERSAMPLE], hr[:300:HR_OVERSAMPLE], FPS, (40, 20), sim_hr=hr[:50], oversample=HR_OVERSAMPLE)
    with pytest.raises(ValueError, match="alignment method"):
        align(hr[::10], hr[::10][:100], FPS, (10, 50), method="dtw")


def test_profile_alignment_picks_the_exact_cycle_of_a_simulation():
    """The recording is the model itself, 7.3 frames in: the profile alignment finds it exactly,
    whereas correlating only the first two cycles may settle on a later, slightly different cycle."""
    cfg = SimConfig(mesh="coarse", dt=1e-4, duration=0.45)
    r = simulate(TABLE3, cfg)
    obs = r.gaw_hr[73::HR_OVERSAMPLE][:300]
    win = alignment_window(obs, FPS, r.gaw.size)
    seg, o, lag = align(r.gaw, obs, FPS, win, sim_hr=r.gaw_hr, oversample=HR_OVERSAMPLE, method="profile")
    assert abs(lag - 7.3) < 1e-6
    assert np.max(np.abs(seg - obs)) < 1e-9


def test_closure_regularisation_makes_the_waveform_continuous_in_the_parameters():
    """With the small-gap regularisation a 1e-3 Pa change of E_cover (1.6e-6 relative) changes the
    aligned GAW by far less than a 1 Pa change does: the response is continuous. (With the hard
    open/closed switch, closure chatter made a 1e-3 Pa change move the coarse-mesh GAW by ~0.2 mm^2.)"""
    cfg = SimConfig(mesh="coarse", dt=1e-4, duration=0.45)
    assert cfg.closure_gap_mm > 0
    base = dataclasses.replace(TABLE3, E_body=11.0, E_cover=740.0)
    r0 = simulate(base, cfg)
    obs = r0.gaw_hr[73::HR_OVERSAMPLE][:300]
    win = alignment_window(obs, FPS, r0.gaw.size)

    def rms(d):
        r = simulate(dataclasses.replace(base, E_cover=base.E_cover + d), cfg)
        s, o, _ = align(r.gaw, obs, FPS, win, sim_hr=r.gaw_hr, oversample=HR_OVERSAMPLE, method="profile")
        return float(np.sqrt(np.mean((s - o) ** 2)))

    small, big = rms(1e-3), rms(1.0)
    assert small < 0.01
    assert big > 20 * small


def test_closure_gap_is_validated():
    with pytest.raises(ValueError, match="closure_gap_mm"):
        SimConfig(closure_gap_mm=-0.01)
    with pytest.raises(ValueError, match="closure_gap_mm"):
        SimConfig(closure_gap_mm=float("nan"))


def test_profile_scores_equal_the_direct_sum_at_every_fine_lag():
    """The correlate/cumsum form of the profile criterion equals the direct windowed sum of
    squared differences at every fine lag (and so picks the same lag)."""
    from vfcore.observe import _profile_scores

    rng = np.random.default_rng(1)
    q, n, j_max = 10, 352, 450
    t = np.arange(9000) / 20000.0
    hr = 10 * np.maximum(np.sin(2 * np.pi * 131 * t), 0) + 0.01 * rng.standard_normal(t.size)
    tmpl = hr[237::q][:n] + 0.3 * rng.standard_normal(n)
    js = np.arange(j_max + 1)
    direct = -np.array([np.sum((hr[j + q * np.arange(n)] - tmpl) ** 2) for j in js])
    fast = _profile_scores(hr, tmpl, q, j_max)
    assert np.max(np.abs(fast - direct)) < 1e-8 * np.max(np.abs(direct))
    assert int(np.argmax(fast)) == int(np.argmax(direct)) == 237


def test_profile_scores_keep_each_template_apart_and_refuse_a_short_record():
    """The template's spectrum is cached: interleaving two templates of the same length,
    and another oversampling, still gives each its own direct sum; a record too short for the
    lags asked is an error, not a wrapped correlation."""
    from vfcore.observe import _profile_scores

    rng = np.random.default_rng(2)
    hr = rng.standard_normal(5000)
    n, j_max = 200, 300
    for q, t in [(10, rng.standard_normal(n)), (10, rng.standard_normal(n)), (7, rng.standard_normal(n))] * 2:
        direct = -np.array([np.sum((hr[j + q * np.arange(n)] - t) ** 2) for j in range(j_max + 1)])
        assert np.max(np.abs(_profile_scores(hr, t, q, j_max) - direct)) < 1e-9 * np.max(np.abs(direct))
    with pytest.raises(ValueError, match="too short"):
        _profile_scores(hr[: 10 * (n - 1) + j_max], rng.standard_normal(n), 10, j_max)


def test_window_search_finds_a_recording_deep_in_a_drifting_simulation():
    """A vibration still drifting across the kept window (its amplitude doubles
    over 600 frames), recorded from frame 137.4 on: the 1.5-period search (lags <= 48 frames)
    can only compare an earlier, smaller part and is left with a misfit of more than 1 mm^2 RMS;
    the whole-window search (every start the 600 simulated frames offer, 200 for 400 recorded)
    finds the recording exactly. For a settled cycle the two agree (same misfit, to rounding)."""
    from vfcore.inference import Prior
    from vfcore.inference.problem import Problem

    q, n, f0 = HR_OVERSAMPLE, 600, 63.7
    t = np.arange(q * (n - 1) + 1) / (q * FPS)
    settled = 20.0 * np.maximum(np.sin(2 * np.pi * f0 * t), 0.0) ** 1.5
    for hr, drifting in ((settled * (1.0 + t / t[-1]), True), (settled, False)):
        obs = np.interp(137.4 + np.arange(400), np.arange(hr.size) / q, hr)
        rms = {}
        for search in ("periods", "window"):
            win = alignment_window(obs, FPS, n, search)
            seg, o, lag = align(hr[::q], obs, FPS, win, sim_hr=hr, oversample=q, method="profile")
            assert o.size == 400
            rms[search] = float(np.sqrt(np.mean((seg - o) ** 2)))
            if search == "window":
                assert win == (200, 400)
                if drifting:
                    assert abs(lag - 137.4) < 1e-3
            else:
                assert win[0] == int(np.ceil(1.5 * FPS / f0))
        if drifting:
            assert rms["periods"] > 1.0 and rms["window"] < 1e-3
        else:
            assert rms["window"] <= rms["periods"] + 1e-9 and rms["periods"] < 0.05
    with pytest.raises(ValueError, match="lag search"):
        alignment_window(obs, FPS, n, "everywhere")
    with pytest.raises(ValueError, match="lag_search"):
        Problem(obs, FPS, Prior.default(), lag_search="everywhere")
    pb = Problem(obs, FPS, Prior.default(), config=SimConfig(duration=0.55, discard=0.25), lag_search="periods")
    assert Problem.from_dict(pb.to_dict()).lag_search == "periods" and pb.window[0] < 200
    assert Problem(obs, FPS, Prior.default(), config=SimConfig(duration=0.55, discard=0.25)).window == (200, 400)


@pytest.mark.parametrize("method", ["profile", "xcorr"])
def test_aligning_many_waveforms_gives_each_the_bytes_of_its_own_alignment(method):
    """The many waveforms one simulation yields under an extension's parameters are aligned in one
    batch: each row's segment and lag are exactly those of aligning it alone, and each recovers its
    own shift (so rows are not mixed up)."""
    from vfcore.observe import align_many

    hr = _signal(n=600)
    t_fine = np.arange(hr.size) / HR_OVERSAMPLE
    obs = np.interp(9.4 + np.arange(300), t_fine, hr)
    shifts = np.array([0.0, 3.2, 11.7, 17.05])  # fine samples of delay per row
    rows = np.stack(
        [np.interp(t_fine - s / HR_OVERSAMPLE, t_fine, hr) * (1 + 0.05 * k) + 0.1 * k for k, s in enumerate(shifts)]
    )
    segs, lags = align_many(rows, obs, FPS, (40, 300), HR_OVERSAMPLE, method=method)
    assert segs.shape == (4, 300) and lags.shape == (4,)
    period = FPS / 63.7
    for k, row in enumerate(rows):
        seg, _, lag = align(
            row[::HR_OVERSAMPLE], obs, FPS, (40, 300), sim_hr=row, oversample=HR_OVERSAMPLE, method=method
        )
        assert np.array_equal(seg, segs[k]) and lag == lags[k]
        d = (lags[k] - (9.4 + shifts[k] / HR_OVERSAMPLE) + period / 2) % period - period / 2
        assert abs(d) < 0.05


@pytest.mark.parametrize("area_scale", [None, (0.5, 2.0)])
def test_a_problems_batch_alignment_and_likelihoods_equal_its_one_by_one(area_scale):
    """``Problem.align_many`` / ``aligned_logliks`` (with and without the area scale's second lag
    search, which runs per row) equal ``Problem.align`` / ``aligned_loglik`` row by row, bit for bit."""
    from vfcore.inference import Prior, Problem
    from vfcore.inference.scoring import aligned_loglik, aligned_logliks

    cfg = SimConfig(mesh="coarse", dt=1e-4, duration=0.45)
    hr = _signal(n=int(round((cfg.duration - cfg.discard) * FPS)) + 1)
    rng = np.random.default_rng(4)
    obs = 1.3 * hr[57::HR_OVERSAMPLE][:300] + 0.3 * rng.standard_normal(300)
    pb = Problem(obs, FPS, Prior.default(), sigma_e=1.0, config=cfg, area_scale=area_scale)
    rows = np.stack([hr * (1.0 + 0.1 * k) for k in range(5)])
    segs = pb.align_many(rows, HR_OVERSAMPLE)
    ll, segs2 = aligned_logliks(rows, pb)
    for k, row in enumerate(rows):
        one = pb.align(row[::HR_OVERSAMPLE], sim_hr=row, oversample=HR_OVERSAMPLE)
        assert np.array_equal(one, segs[k]) and np.array_equal(one, segs2[k])
        assert ll[k] == aligned_loglik(row, pb)[0]
    assert len(set(ll.tolist())) == 5


def test_aligning_many_refuses_records_shorter_than_the_window():
    from vfcore.observe import align_many

    hr = _signal(n=200)
    with pytest.raises(ValueError, match="shorter than the 300 frames"):
        align_many(np.stack([hr, hr]), hr[::HR_OVERSAMPLE], FPS, (40, 300), HR_OVERSAMPLE)
    with pytest.raises(ValueError, match="oversample"):
        align_many(np.stack([hr, hr]), hr[::HR_OVERSAMPLE], FPS, (40, 100), 0)
