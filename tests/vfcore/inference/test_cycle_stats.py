"""The summary-statistics likelihood: blind to phase, sharp in amplitude and period."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vfcore.inference.cycle_stats import CycleStatsLikelihood

FPS = 2000.0


def pulses(n, f0=100.0, amp=20.0, phase=0.0, mod=0.0, seed=None):
    """A GAW-like train of half-sine pulses (closed 30 % of each cycle), optionally with random per-cycle
    amplitude modulation ``mod`` (relative sd)."""
    t = np.arange(n) / FPS
    ph = (t * f0 + phase) % 1.0
    g = np.where(ph < 0.7, np.sin(np.pi * ph / 0.7), 0.0)
    if mod:
        rng = np.random.default_rng(seed)
        cyc = np.floor(t * f0 + phase).astype(int)
        g = g * (1.0 + mod * rng.standard_normal(cyc.max() + 1))[cyc]
    return amp * g


def test_a_phase_shift_costs_a_tenth_of_what_it_costs_frame_by_frame():
    """Statistics blind to phase: a shift moves them only through where the frames sample each cycle (20 frames
    a cycle here), a small fraction of what it costs the frame-by-frame likelihood."""
    obs = pulses(400, phase=0.0) + np.random.default_rng(1).normal(0, 1.0, 400)
    lik = CycleStatsLikelihood(obs, FPS, sigma_e=1.0)
    base = lik(pulses(600, phase=0.0))
    for phase in (0.13, 0.5, 0.81):
        shifted = pulses(600, phase=phase)
        frames = 0.5 * np.sum((shifted[-400:] - obs) ** 2) - 0.5 * np.sum((pulses(600)[-400:] - obs) ** 2)
        assert abs(lik(shifted) - base) < 0.1 * frames


def test_amplitude_and_period_are_resolved():
    obs = pulses(400) + np.random.default_rng(2).normal(0, 1.0, 400)
    lik = CycleStatsLikelihood(obs, FPS, sigma_e=1.0)
    best = lik(pulses(600))
    assert lik(pulses(600, amp=24.0)) < best - 20.0
    assert lik(pulses(600, f0=110.0)) < best - 20.0


def test_cycle_to_cycle_variation_widens_the_statistics():
    """A modulated observation is less informative: the same 10 % amplitude error costs fewer nats."""
    clean = CycleStatsLikelihood(pulses(400), FPS, sigma_e=0.1)
    modulated = CycleStatsLikelihood(pulses(400, mod=0.1, seed=3), FPS, sigma_e=0.1)
    d_clean = clean(pulses(600)) - clean(pulses(600, amp=22.0))
    d_mod = modulated(pulses(600, mod=0.1, seed=4)) - modulated(pulses(600, amp=22.0, mod=0.1, seed=4))
    assert d_mod < d_clean


def test_bad_input():
    with pytest.raises(ValueError, match="no periodic oscillation"):
        CycleStatsLikelihood(np.zeros(400), FPS, sigma_e=1.0)
    lik = CycleStatsLikelihood(pulses(400), FPS, sigma_e=1.0)
    assert lik(pulses(100)) == -math.inf
    assert lik(np.full(600, np.nan)) == -math.inf
