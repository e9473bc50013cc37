"""GAW measures against analytic waveforms (expected values are derived, not recorded)."""

import math

import numpy as np
import pytest

from vfcore import measures as M


def half_rectified_sine(f0=100.0, fps=10000.0, n_cycles=12):
    t = np.arange(int(n_cycles * fps / f0)) / fps
    return np.maximum(0.0, np.sin(2 * np.pi * f0 * t)), fps


def triangle_train(closed=10, rise=20, fall=10, amp=2.0, offset=0.0, n_cycles=10):
    one = np.concatenate([np.zeros(closed), np.arange(rise) / rise, 1.0 - np.arange(fall) / fall]) * amp
    return np.tile(one, n_cycles) + offset


def test_estimate_f0_sine():
    fps = 2000.0
    t = np.arange(600) / fps
    assert M.estimate_f0(np.sin(2 * np.pi * 123.4 * t), fps) == pytest.approx(123.4, abs=0.1)
    assert math.isnan(M.estimate_f0(np.ones(100), fps))


def test_half_rectified_sine_quotients():
    x, fps = half_rectified_sine()
    # open exactly half of the time, symmetric opening/closing
    # (level 1e-9 rather than 0: sin(k pi) is +-1e-16 in floating point)
    assert M.open_quotient(x, fps, level=1e-9) == pytest.approx(0.5, abs=1e-6)
    assert M.speed_quotient(x, fps, level=1e-9) == pytest.approx(1.0, abs=1e-6)
    assert M.closing_quotient(x, fps, level=1e-9) == pytest.approx(0.25, abs=1e-6)
    # with a threshold at level*amplitude: open while sin > level
    lev = 0.05
    oq = (math.pi - 2 * math.asin(lev)) / (2 * math.pi)
    assert M.open_quotient(x, fps, level=lev) == pytest.approx(oq, abs=2e-4)
    assert M.glottal_gap_index(x, fps) == pytest.approx(0.0, abs=1e-12)
    # NAQ: peak-to-peak 1, steepest closing slope omega -> NAQ = 1/(omega T) = 1/(2 pi)
    assert M.naq(x, fps) == pytest.approx(1 / (2 * math.pi), rel=5e-3)


def test_half_rectified_sine_hrf():
    x, fps = half_rectified_sine()
    # Fourier series: 1/pi + sin/2 - (2/pi) sum_{k even} cos(k w t)/(k^2-1)
    h1 = 0.5
    hk = [2 / (math.pi * (k * k - 1)) for k in range(2, 11, 2)]
    expected = 10 * math.log10(sum(h * h for h in hk) / h1**2)
    assert M.harmonic_richness_factor(x, fps, n_harmonics=10) == pytest.approx(expected, abs=0.02)


@pytest.mark.parametrize("level", [0.0, 0.05])
def test_triangle_pulse(level):
    closed, rise, fall, fps = 10, 20, 10, 4000.0
    x = triangle_train(closed, rise, fall)
    T = closed + rise + fall
    s = 1.0 - level
    assert M.open_quotient(x, fps, level) == pytest.approx(s * (rise + fall) / T, abs=1e-9)
    assert M.speed_quotient(x, fps, level) == pytest.approx(rise / fall, abs=1e-9)
    assert M.closing_quotient(x, fps, level) == pytest.approx(s * fall / T, abs=1e-9)
    # linear closing ramp: AQ = T_cl, NAQ = T_cl / T
    assert M.amplitude_quotient(x, fps) == pytest.approx(fall / fps, rel=1e-9)
    assert M.naq(x, fps) == pytest.approx(fall / T, rel=1e-9)
    assert M.jitter(x, fps) == pytest.approx(0.0, abs=1e-12)
    assert M.shimmer(x, fps) == pytest.approx(0.0, abs=1e-12)


def test_glottal_gap_index_incomplete_closure():
    x = triangle_train(amp=2.0, offset=0.5)
    assert M.glottal_gap_index(x, 4000.0) == pytest.approx(0.5 / 2.5, abs=1e-12)


def test_sine_harmonic_content():
    fps, f0 = 8000.0, 100.0
    t = np.arange(2400) / fps
    w = 2 * np.pi * f0 * t
    a2, a3 = 0.4, 0.3
    x = 2 + np.sin(w) + a2 * np.sin(2 * w + 0.7) + a3 * np.cos(3 * w)
    assert M.estimate_f0(x, fps) == pytest.approx(f0, abs=0.05)
    h = M.harmonic_amplitudes(x, fps, 5)
    np.testing.assert_allclose(h, [1.0, a2, a3, 0.0, 0.0], atol=1e-6)
    assert M.harmonic_richness_factor(x, fps) == pytest.approx(10 * math.log10(a2**2 + a3**2), abs=1e-6)
    assert M.subharmonic_to_harmonic_ratio(x, fps) == pytest.approx(0.0, abs=1e-9)


def test_period_doubling_shr():
    fps, f0, b = 8000.0, 100.0, 0.2
    t = np.arange(3200) / fps
    w = 2 * np.pi * f0 * t
    x = 3 + np.sin(w) + b * np.sin(w / 2)
    # f0 stays at the fundamental, the subharmonic at f0/2 has amplitude b
    assert M.estimate_f0(x, fps) == pytest.approx(f0, abs=0.5)
    assert M.subharmonic_to_harmonic_ratio(x, fps) == pytest.approx(b, abs=1e-6)


def raised_cosine_cycles(lengths, amps):
    return np.concatenate([a * 0.5 * (1 - np.cos(2 * np.pi * np.arange(n) / n)) for n, a in zip(lengths, amps)])


def test_alternating_amplitude_shimmer():
    n = 40
    amps = [1.0, 0.8] * 8
    x = raised_cosine_cycles([n] * len(amps), amps)
    fps = 4000.0
    b = M.cycle_boundaries(x, fps)
    # every |a_k - a_{k+1}| is 0.2; the mean amplitude is over the complete cycles
    a = np.array([amps[(k + n // 2) // n] for k in b[:-1]])
    assert M.shimmer(x, fps) == pytest.approx(0.2 / a.mean(), rel=1e-9)
    assert M.jitter(x, fps) == pytest.approx(0.0, abs=1e-12)
    assert M.subharmonic_to_harmonic_ratio(x, fps) > 0.02


def test_alternating_period_jitter():
    lengths = [38, 42] * 8
    x = raised_cosine_cycles(lengths, [1.0] * len(lengths))
    fps = 4000.0
    assert M.jitter(x, fps) == pytest.approx(4 / 40, rel=1e-9)
    assert M.shimmer(x, fps) == pytest.approx(0.0, abs=1e-12)


def test_gaw_measures_dict():
    x, fps = half_rectified_sine()
    d = M.gaw_measures(x, fps)
    for key in (
        "f0_hz",
        "n_cycles",
        "open_quotient",
        "speed_quotient",
        "closing_quotient",
        "amplitude_quotient_s",
        "naq",
        "glottal_gap_index",
        "hrf_db",
        "jitter",
        "shimmer",
        "shr",
    ):
        assert key in d
    assert d["f0_hz"] == pytest.approx(100.0, abs=0.05)
    assert d["open_quotient"] == pytest.approx(M.open_quotient(x, fps), abs=1e-12)
    assert d["n_cycles"] >= 10
    with pytest.raises(ValueError):
        M.gaw_measures(x, 0.0)
    with pytest.raises(ValueError):
        M.gaw_measures(np.array([1.0, np.nan, 2.0]), fps)


def test_cycle_boundaries_at_minima():
    x = triangle_train()
    b = M.cycle_boundaries(x, 4000.0)
    assert np.all(np.diff(b) == 40)
    assert np.all(x[b] == 0.0)
