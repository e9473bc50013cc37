"""The regularity check of the base fit (vfcore.diagnose.regularity)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from vfcore.diagnose.regularity import aperiodicity, sensitivity
from vfcore.inference import Prior
from vfcore.inference.problem import Problem

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))
from benchmarks.bench_regularity import CFG, FIXED, recording  # noqa: E402  (the suites' window and fixed values)

FPS = 2000.0


def _problem_at(theta, prior, seed):
    return Problem(recording(theta, prior, CFG, sigma=0.5, seed=seed), FPS, prior, config=CFG)


def test_regular_and_irregular_vibration_told_apart():
    """At one concealed recording's base fit (E_body 9.8, E_cover 562 Pa, p_sub 1,274 Pa) the limit
    cycle is regular: a 1e-6 relative change of the parameters moves the log-likelihood of a
    recording made from that very point by far less than a nat. At another's (10.0, 912, 1,783) the
    vibration is irregular and the same change moves it by hundreds of nats or more."""
    prior = Prior.default(fixed=FIXED)
    regular = np.array([9.763560880049237, 562.201183299505, 1273.7606383329155])  # case 10's base fit
    s = sensitivity(_problem_at(regular, prior, 1), regular)
    assert not s.irregular and s.max_change < 0.1, s
    assert s.n_simulations == 7 and len(s.changes) == 2 and len(s.second_differences) == 2
    chaotic = np.array([10.04932783349597, 912.2302017130069, 1783.1509696509981])
    c = sensitivity(_problem_at(chaotic, prior, 2), chaotic)
    assert c.irregular and c.max_change > 100.0, c


def test_aperiodicity_of_repeating_and_modulated_waveforms():
    """A waveform that repeats after one or two cycles scores 0; one modulated at an incommensurate
    frequency f_m scores the analytic cost of its best shift: the mean of (B sin(w t) - B sin(w (t + kT)))^2
    is B^2 (1 - cos(2 pi k f_m / f0)), smallest at k = 3 for f_m = f0 / phi^2, so 400 frames at sigma 1
    cost 400 * 0.3923 B^2 / 2 nats."""
    fps, over, f0 = 2000.0, 10, 100.0
    t = np.arange(int(0.5 * fps * over)) / (fps * over)
    base = 20 + 15 * np.sin(2 * np.pi * f0 * t) + 5 * np.sin(4 * np.pi * f0 * t + 0.3)
    assert aperiodicity(base, f0, fps, over, 400, 1.0) < 1e-6
    doubled = base + 2 * np.sin(np.pi * f0 * t)  # period two: repeats after 2 cycles
    assert aperiodicity(doubled, f0, fps, over, 400, 1.0) < 1e-6
    fm = f0 / ((1 + 5**0.5) / 2) ** 2
    expected = 400 * (1 - np.cos(2 * np.pi * 3 * fm / f0)) / 2
    got = aperiodicity(base + np.sin(2 * np.pi * fm * t), f0, fps, over, 400, 1.0)
    assert got == pytest.approx(expected, rel=0.05), (got, expected)
    assert aperiodicity(base + np.sin(2 * np.pi * fm * t), f0, fps, over, 400, 2.0) == pytest.approx(got / 4)
    short = aperiodicity((base + np.sin(2 * np.pi * fm * t))[:4000], f0, fps, over, 400, 1.0)
    assert short == pytest.approx(expected, rel=0.1), (short, expected)  # 4 cycles left of 20: read over 16
    assert np.isnan(aperiodicity(base[:1000], f0, fps, over, 400, 1.0))  # under 2 cycles left: no verdict
    assert np.isnan(aperiodicity(base, float("nan"), fps, over, 400, 1.0))


def test_a_staircase_likelihood_is_flagged_rough_and_a_smooth_one_is_not():
    """Two six-parameter calibration twins (paper prior, coarse mesh, compliant layer, dt 5e-5 s): at
    seed 2000's truth the peaks of the cycles are modulated (they do not repeat within 8 cycles) and the
    likelihood jumps by tens of nats between points a relative 1e-4 apart, which the 1e-6 check cannot
    see; at seed 2001's truth the limit cycle repeats and both measures stay below a nat."""
    from vfcore.config import SimConfig
    from vfcore.inference import make_twin
    from vfcore.params import TABLE3

    prior = Prior.default(fixed={"x0": TABLE3.x0})
    cfg = SimConfig(mesh="coarse", dt=5e-5, duration=0.55, contact="layer")
    rough = make_twin(prior, cfg, seed=2000, sigma_e=1.0, n_obs=400)
    s = sensitivity(rough.problem, rough.truth)
    assert not s.irregular and s.rough and not s.smooth, s
    assert s.aperiodicity > 30 and s.max_second_difference > 10, s
    from worker.reduce import regularity_warning

    assert regularity_warning(s.to_dict()).startswith("ROUGH LIKELIHOOD: at the heaviest sample")
    smooth = make_twin(prior, cfg, seed=2001, sigma_e=1.0, n_obs=400)
    s = sensitivity(smooth.problem, smooth.truth)
    assert s.smooth and s.aperiodicity < 1 and s.max_second_difference < 1, s
    assert regularity_warning(s.to_dict()) is None
    off = sensitivity(smooth.problem, smooth.truth, rough_step=0.0)
    assert off.n_simulations == 3 and off.second_differences == () and off.loglik == s.loglik


def test_sensitivity_rejects_bad_input():
    prior = Prior.default(fixed=FIXED)
    pb = Problem(10 + 5 * np.sin(2 * np.pi * 120 * np.arange(300) / FPS), FPS, prior, config=CFG)
    with pytest.raises(ValueError, match="free parameters"):
        sensitivity(pb, [1.0, 2.0])
    with pytest.raises(ValueError, match="step"):
        sensitivity(pb, [9.0, 700.0, 900.0], step=0.0)
    with pytest.raises(ValueError, match="rough_step"):
        sensitivity(pb, [9.0, 700.0, 900.0], rough_step=-1e-4)


def test_local_check_counts_the_roughness_as_an_error():
    """A concealed leak at high p_sub: leak beat the base refitted in its mode by 1,426 +- 0.8 nats and was
    named on the local comparison; the base fit's vibration was irregular (a 1e-6 relative change
    moved the log-likelihood by up to 81,000 nats). With the roughness in the error it is not
    named; at a regular base's roughness (0.01 nats) it is."""
    from vfcore.diagnose.amend import local_passes

    ok, se = local_passes(1426.0, 0.7, 0.4, 80994.6)
    assert not ok and se > 80000
    ok, se = local_passes(1426.0, 0.7, 0.4, 0.01)
    assert ok and se < 1.0
    assert not local_passes(2.5, 0.1, 0.1, 0.0)[0]  # below min_gain = 3 nats
    assert not local_passes(float("nan"), 0.1, 0.1, 0.0)[0]


def test_the_rough_phrase_names_what_was_measured_and_skips_a_missing_verdict():
    """A check without an aperiodicity verdict (NaN: under two cycles) is described by its second differences
    alone, never as 'costs nan nats'."""
    from vfcore.diagnose.regularity import Sensitivity, rough_phrase

    both = Sensitivity(
        step=1e-6,
        tol=1.0,
        loglik=-500.0,
        changes=(0.1,),
        irregular=False,
        n_simulations=7,
        rough_step=1e-4,
        second_differences=(0.5, 12.0),
        aperiodicity=40.0,
        rough=True,
    )
    p = rough_phrase(both.to_dict())
    assert "costs 40 nats" in p and "second difference of 12 nats" in p
    none = Sensitivity(
        step=1e-6,
        tol=1.0,
        loglik=-500.0,
        changes=(0.1,),
        irregular=False,
        n_simulations=7,
        rough_step=1e-4,
        second_differences=(5.0,),
        aperiodicity=float("nan"),
        rough=True,
    )
    p = rough_phrase(none.to_dict())
    assert "nan" not in p and "repeat" not in p and p.startswith("a relative 0.0001 change")
