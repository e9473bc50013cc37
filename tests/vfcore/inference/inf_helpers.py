"""Helpers for the inference tests (a module with a unique name: ``conftest`` is ambiguous when
several test folders are collected together)."""

from __future__ import annotations

import math

import numpy as np

from vfcore.config import SimConfig
from vfcore.params import Params
from vfcore.result import CycleSummary, SimResult


def synthetic_gaw(f0=120.0, fps=2000.0, n=600, amp=10.0, phase=0.0, noise=0.0, seed=0):
    t = np.arange(n) / fps
    y = amp * np.maximum(np.sin(2 * math.pi * f0 * t + phase), 0.0)
    if noise:
        y = y + noise * np.random.default_rng(seed).standard_normal(n)
    return y


class FakeSimulator:
    """Analytic stand-in for ``vfcore.forward.simulate``: a half-rectified sine whose
    frequency follows E_body and amplitude p_sub. Fails (ok=False) for p_sub < 450 and
    raises for E_lig > 2.9, so failure handling is exercised. Picklable."""

    def __call__(self, params: Params, config: SimConfig) -> SimResult:
        if params.E_lig > 2.9:
            raise FloatingPointError("synthetic blow-up")
        if params.p_sub < 450:
            return SimResult(ok=False, message="synthetic divergence", params=params, config=config, fps=config.fps)
        n = int(math.floor((config.duration - config.discard) * config.fps + 1e-9)) + 1
        t = np.arange(n) / config.fps
        f0 = 100.0 + 5.0 * (params.E_body - 12.0)
        amp = params.p_sub / 100.0
        gaw = amp * np.maximum(np.sin(2 * math.pi * f0 * t + 0.7), 0.0)
        flow = 1e-4 * gaw / amp
        cp = np.tile((amp * 10.0 * np.maximum(-np.sin(2 * math.pi * f0 * t), 0.0))[:, None], (1, 3))
        cyc = CycleSummary(
            t_start=np.zeros(2),
            period=np.full(2, 1 / f0),
            peak_area=np.full(2, amp),
            min_area=np.zeros(2),
            mean_flow=np.full(2, flow.mean()),
            mean_peak_contact_pressure_unconverged=np.full(2, cp.max(axis=1).mean()),
            max_contact_pressure_unconverged=np.full(2, cp.max()),
            contact_impulse=np.full(2, 1e-3 * amp),
            contact_duration=np.full(2, 0.5 / f0),
            contact_pressure_in_contact=np.full(2, 5.0 * amp),
        )
        return SimResult(
            ok=True,
            message="",
            params=params,
            config=config,
            fps=config.fps,
            t=t,
            gaw=gaw,
            width=gaw / config.length_mm,
            flow=flow,
            contact_pressure=cp,
            cycles=cyc,
        )
