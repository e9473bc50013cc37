"""The regularity check of the base fit (vfcore.diagnose.regularity)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from vfcore.diagnose.regularity import sensitivity
from vfcore.inference import Prior
from vfcore.inference.problem import Problem

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))
from benchmarks.bench_regularity import CFG, FIXED, recording  # noqa: E402  (the suites' window and fixed values)

FPS = 2000.0


def _problem_at(theta, prior, seed):
    return Problem(recording(theta, prior, CFG, sigma=0.5, seed=seed), FPS, prior, config=CFG)


def test_regular_and_irregular_vibration_told_apart():
    """At the base fit of concealed case 10 of seed 4 (E_body 9.8, E_cover 562 kPa, p_sub 1,274 Pa) the limit
    cycle is regular: a 1e-6 relative change of the parameters moves the log-likelihood of a
    recording made from that very point by far less than a nat. At case 06's (10.0, 912, 1,783) the
    vibration is irregular and the same change moves it by hundreds of nats or more."""
    prior = Prior.default(fixed=FIXED)
    regular = np.array([9.763560880049237, 562.201183299505, 1273.7606383329155])   # case 10's base fit
    s = sensitivity(_problem_at(regular, prior, 1), regular)
    assert not s.irregular and s.max_change < 0.1, s
    assert s.n_simulations == 7 and len(s.changes) == 2 and len(s.second_differences) == 2
    chaotic = np.array([10.04932783349597, 912.2302017130069, 1783.1509696509981])
    c = sensitivity(_problem_at(chaotic, prior, 2), chaotic)
    assert c.irregular and c.max_change > 100.0, c


def test_sensitivity_rejects_bad_input():
    prior = Prior.default(fixed=FIXED)
    pb = Problem(10 + 5 * np.sin(2 * np.pi * 120 * np.arange(300) / FPS), FPS, prior, config=CFG)
    with pytest.raises(ValueError, match="free parameters"):
        sensitivity(pb, [1.0, 2.0])
    with pytest.raises(ValueError, match="step"):
        sensitivity(pb, [9.0, 700.0, 900.0], step=0.0)


def test_local_check_counts_the_roughness_as_an_error():
    """Concealed case 06 of seed 4: leak beat the base refitted in its mode by 1,426 +- 0.8 nats and was
    named on the local comparison; the base fit's vibration was irregular (a 1e-6 relative change
    moved the log-likelihood by up to 81,000 nats). With the roughness in the error it is not
    named; at a regular base's roughness (0.01 nats) it is."""
    from vfcore.diagnose.amend import local_passes
    ok, se = local_passes(1426.0, 0.7, 0.4, 80994.6)
    assert not ok and se > 80000
    ok, se = local_passes(1426.0, 0.7, 0.4, 0.01)
    assert ok and se < 1.0
    assert not local_passes(2.5, 0.1, 0.1, 0.0)[0]            # below min_gain = 3 nats
    assert not local_passes(float("nan"), 0.1, 0.1, 0.0)[0]
