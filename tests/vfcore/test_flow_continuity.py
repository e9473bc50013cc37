"""The waveform moves continuously with the parameters under the continuous flow load, and jumps under the
paper's node-wise rule: a system-level check across the switches a real trajectory goes through.

Table 3 on the coarse mesh with the contact layer, the first 100 ms (opening, closures, separation moving along
the surface), the density scanned over ±1e-3 relative; the largest change of the GAW between neighbours is
bisected 30 times. A continuous map's change shrinks with the step (here by about 2^30); a switch keeps it.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from vfcore import TABLE3, SimConfig, simulate
from vfcore.params import PARAM_NAMES, Params


def _gaw(s, flow):
    p = TABLE3.as_array().copy()
    p[PARAM_NAMES.index("rho")] *= 1.0 + s
    cfg = SimConfig(mesh="coarse", dt=5e-5, duration=0.1, discard=0.0, contact="layer", flow=flow, early_stop=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = simulate(Params.from_array(p), cfg)
    assert r.ok, r.message
    return r.gaw


def _bisected_change(flow, halvings=30):
    ss = np.linspace(-1e-3, 1e-3, 21)
    G = np.array([_gaw(s, flow) for s in ss])
    dif = np.max(np.abs(np.diff(G, axis=0)), axis=1)
    k = int(np.argmax(dif))
    a, b, Ga, Gb = ss[k], ss[k + 1], G[k], G[k + 1]
    for _ in range(halvings):
        c = 0.5 * (a + b)
        Gc = _gaw(c, flow)
        if np.max(np.abs(Gc - Ga)) >= np.max(np.abs(Gb - Gc)):
            b, Gb = c, Gc
        else:
            a, Ga = c, Gc
    return float(dif[k]), float(np.max(np.abs(Gb - Ga)))


@pytest.mark.parametrize(
    "flow",
    [
        "continuous",
        pytest.param(
            "paper",
            marks=pytest.mark.xfail(
                reason="the paper's node-wise load switches: the GAW jumps by a fixed amount however small the step",
                strict=False,
            ),
        ),
    ],
)
def test_gaw_is_continuous_in_the_parameters(flow):
    first, last = _bisected_change(flow)
    assert first > 1e-3  # the scan crosses something: the waveform does move
    assert last < 1e-5 * first, (first, last)
