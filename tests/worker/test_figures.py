"""Job figures render for every posterior the reducer can meet, degenerate ones included."""

from types import SimpleNamespace

import numpy as np
import pytest

from worker.figures import fig_corner


@pytest.mark.parametrize("distinct", [1, 3, 200])
def test_pair_plot_renders_degenerate_and_regular_ensembles(distinct):
    """An importance-sampling run with ESS ~ 1 resamples one draw N times: there is no density to
    smooth, and the figure must still be drawn (scatter and histograms)."""
    rng = np.random.default_rng(0)
    base = np.array([12.0, 600.0, 1000.0]) + rng.normal(size=(distinct, 3)) * [0.5, 20.0, 30.0]
    x = base[rng.integers(0, distinct, 200)]
    png = fig_corner(SimpleNamespace(resampled_samples=x, names=("E_body", "E_cover", "p_sub")))
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000
