"""Exact group moves along the common scale (vfcore.inference.symmetry) and the SMC walk in log coordinates.

The target here is a toy with the model's structure: a likelihood that depends on ratios only (so it is
invariant under theta -> c theta on all coordinates), a uniform box prior, and optionally a Gaussian
measurement of one coordinate that anchors the scale. Its exact posterior moments come from importance
sampling of 2,000,000 prior draws (the likelihood is analytic and cheap)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from vfcore import TABLE3, SimConfig, simulate
from vfcore.inference import Prior, Problem, evaluate
from vfcore.inference.identify import SCALED
from vfcore.inference.smc import SMCSampler
from vfcore.inference.symmetry import ScaleGroup, rescale_products, scale_group

BOUNDS = {"E_body": (1.0, 3.0), "E_lig": (2.0, 5.0), "p_sub": (0.5, 2.0)}
PRIOR = Prior(BOUNDS)
MEAS = (1, 3.0, 0.3)  # a measurement of the second coordinate: mean 3, sd 0.3


def _loglik(th):
    th = np.atleast_2d(th)
    a = np.log(th[:, 0] / th[:, 1]) - math.log(0.6)
    b = np.log(th[:, 2] / th[:, 1]) - math.log(0.3)
    return -0.5 * (a / 0.05) ** 2 - 0.5 * (b / 0.08) ** 2


def _offset(th):
    j, m, sd = MEAS
    z = (np.atleast_2d(th)[:, j] - m) / sd
    return -0.5 * z * z


def _exact_moments(measured: bool, n=2_000_000, seed=7):
    th = PRIOR.sample(n, np.random.default_rng(seed))
    lw = _loglik(th) + (_offset(th) if measured else 0.0)
    w = np.exp(lw - lw.max())
    w /= w.sum()
    mean = w @ th
    sd = np.sqrt(w @ (th - mean) ** 2)
    return mean, sd, th, w


def _target_draws(measured: bool, n: int, seed: int):
    _, _, th, w = _exact_moments(measured)
    idx = np.random.default_rng(seed).choice(th.shape[0], size=n, p=w)
    return th[idx]


@pytest.mark.parametrize("measured", [False, True])
def test_a_group_move_leaves_the_target_invariant(measured):
    """Draws of the target, each moved once along its orbit, are still draws of the target (two-sample
    Kolmogorov–Smirnov on the log-scale and on each coordinate); the ratios do not change at all."""
    g = ScaleGroup(PRIOR, np.arange(3), _offset if measured else None)
    x = _target_draws(measured, 20_000, seed=1)
    y, t, d = g.move(x, 1.0, np.random.default_rng(2))
    assert np.all(PRIOR.contains(y))
    assert np.allclose(np.log(y[:, 0] / y[:, 1]), np.log(x[:, 0] / x[:, 1]), atol=1e-12)
    assert np.allclose(y, x * np.exp(t)[:, None], rtol=1e-12)
    assert np.allclose(d, (_offset(y) - _offset(x)) if measured else 0.0, atol=1e-9)
    assert np.std(t) > 0.05  # it moved
    ref = _target_draws(measured, 20_000, seed=3)
    for a, b in ((np.log(y).sum(axis=1), np.log(ref).sum(axis=1)), (y[:, 0], ref[:, 0]), (y[:, 2], ref[:, 2])):
        assert stats.ks_2samp(a, b).pvalue > 1e-3


@pytest.mark.parametrize("measured", [False, True])
@pytest.mark.parametrize("symmetric", [False, True])
def test_smc_in_log_coordinates_recovers_the_exact_posterior(measured, symmetric):
    """SMC with the walk in log coordinates, with and without exact group moves along the scale, agrees
    with the exact posterior: means within 0.15 sd, sds within 15 %."""
    mean, sd, _, _ = _exact_moments(measured)
    group = ScaleGroup(PRIOR, np.arange(3), _offset if measured else None) if symmetric else None

    def fn(th):
        return _loglik(th) + (_offset(th) if measured else 0.0)

    s = SMCSampler(PRIOR, 1500, seed=4, coords="log", symmetry=group, max_moves=6)
    while (th := s.ask()) is not None:
        s.tell(fn(th))
    post = s.result()
    m = post.mean
    sdev = post.sd
    assert np.all(np.abs(m - mean) < 0.15 * sd), (m, mean, sd)
    assert np.all(np.abs(sdev / sd - 1.0) < 0.15), (sdev, sd)


def test_invalid_symmetry_options_are_refused():
    with pytest.raises(ValueError, match="log coordinates"):
        SMCSampler(PRIOR, 20, symmetry=ScaleGroup(PRIOR, np.arange(3)), coords="linear")
    with pytest.raises(ValueError, match="lower bound"):
        SMCSampler(Prior({"E_body": (0.0, 1.0)}), 20, coords="log")
    with pytest.raises(ValueError, match="coords"):
        SMCSampler(PRIOR, 20, coords="polar")
    with pytest.raises(ValueError, match="distinct"):
        ScaleGroup(PRIOR, np.array([0, 0]))


CFG = SimConfig(mesh="coarse", dt=1e-4, duration=0.3, discard=0.1, fps=2000.0)


def test_the_fe_problem_has_the_group_and_its_products_scale_like_a_simulation():
    """For an FE problem estimating all six scaled parameters, a group move needs no simulation: the
    log-likelihood of the moved draw and its products, scaled in closed form, equal those of simulating
    it (round-off aside). A problem with one of the six fixed has no exact symmetry."""
    full = Prior.default(fixed={"x0": TABLE3.x0})
    theta = np.array([[getattr(TABLE3, n) for n in full.names]])
    obs = simulate(TABLE3, CFG).gaw[:150]
    prob = Problem(obs + 0.1, 2000.0, full, sigma_e=0.5, config=CFG, measurements={"p_sub": (900.0, 60.0)})
    g = scale_group(prob)
    assert g is not None and [full.names[i] for i in g.idx] == list(SCALED)
    assert scale_group(Problem(obs, 2000.0, Prior.default(fixed={"x0": 8.4, "rho": 1051.0}), config=CFG)) is None
    c = 1.07
    moved = g.scaled(theta, np.array([math.log(c)]))
    ev0, ev1 = evaluate(theta, prob), evaluate(moved, prob)
    d = g.offset(moved) - g.offset(theta)
    pred = rescale_products(ev0, np.array([math.log(c)]), d)
    assert abs(pred.loglik[0] - ev1.loglik[0]) < 1e-6 * abs(ev1.loglik[0])
    for name in ("mean_flow", "mean_contact", "max_contact", "contact_impulse", "contact_pressure_in_contact"):
        a, b = getattr(pred, name)[0], getattr(ev1, name)[0]
        assert abs(a - b) <= 1e-6 * abs(b), name
    assert abs(ev1.max_contact[0] / ev0.max_contact[0] - c) < 1e-6
