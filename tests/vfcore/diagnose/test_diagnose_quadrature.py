"""Integrating waveform-level extension parameters out of each simulation's likelihood
(vfcore.diagnose.quadrature, ExtendedEvaluator(integrate=True))."""

import math

import numpy as np
import pytest
from scipy.special import logsumexp
from scipy.stats import norm

from vfcore.config import SimConfig
from vfcore.diagnose.fit import ExtendedEvaluator, ExtendedPrior, observe_extended
from vfcore.diagnose.quadrature import integrate_loglik
from vfcore.forward import simulate
from vfcore.inference import Prior
from vfcore.inference.problem import Problem, gaussian_loglik
from vfcore.observe import align
from vfcore.params import PARAM_NAMES, TABLE3
from vfcore.result import HR_OVERSAMPLE

FPS = 2000.0
CFG = SimConfig(mesh="coarse", dt=1e-4, duration=0.35, discard=0.15)


def _gauss(c, s, level=0.0):
    c, s = np.atleast_1d(c), np.atleast_1d(s)
    return lambda p: level - 0.5 * np.sum(((p - c) / s) ** 2, axis=1)


@pytest.mark.parametrize("c,s", [(0.4371, 1e-3), (0.13, 2e-4), (0.5, 0.08)])
def test_quadrature_integrates_a_gaussian_peak_of_any_width(c, s):
    """log of the prior mean of a Gaussian likelihood on [0, 1] (mass inside the box by the
    normal cdf), its mean and sd; peaks far narrower than the coarse cells included."""
    r = integrate_loglik(_gauss(c, s, 700.0), [0.0], [1.0], n0=24)
    inside = norm.cdf((1 - c) / s) - norm.cdf(-c / s)
    want = 700.0 + math.log(s * math.sqrt(2 * math.pi) * inside)
    assert abs(r.log_mean - want) < 0.02
    assert abs(r.mean[0] - c) < 0.05 * s
    assert abs(r.sd[0] / s - 1) < 0.15
    assert r.n_evals < 120


def test_quadrature_truncated_peak_and_two_dimensions():
    # a peak at the bound: half its mass
    r = integrate_loglik(_gauss(1.0, 0.01), [0.0], [1.0], n0=24)
    assert abs(r.log_mean - math.log(0.01 * math.sqrt(2 * math.pi) / 2)) < 0.03
    # 2-D, unequal widths, box [0, 0.4] x [0.5, 1.5]
    r = integrate_loglik(_gauss([0.31, 1.2], [0.003, 0.02]), [0.0, 0.5], [0.4, 1.5], n0=8, rounds=6)
    assert abs(r.log_mean - math.log(2 * math.pi * 0.003 * 0.02 / 0.4)) < 0.05
    assert abs(r.mean[0] - 0.31) < 3e-4 and abs(r.mean[1] - 1.2) < 2e-3
    # a flat likelihood: log mean 0, the uniform's mean and sd
    r = integrate_loglik(lambda p: np.zeros(len(p)), [2.0], [4.0], n0=10)
    assert abs(r.log_mean) < 1e-12 and abs(r.mean[0] - 3.0) < 1e-12
    assert abs(r.sd[0] - 2 / math.sqrt(12)) < 1e-9
    with pytest.raises(ValueError, match="lo < hi"):
        integrate_loglik(lambda p: np.zeros(len(p)), [1.0], [1.0])


@pytest.fixture(scope="module")
def base_run():
    return simulate(TABLE3, CFG)


@pytest.mark.parametrize(
    "name,phi,n_dense", [("scale", {"scale": 1.13}, 4001), ("frame_rate", {"rate_ratio": 1.037}, 8001)]
)
def test_integrated_likelihood_equals_a_dense_grid_average(base_run, name, phi, n_dense):
    """The evaluator's integrated log-likelihood of one simulation equals the log of the average
    likelihood over a dense grid of the parameter's prior (the definition of the integral), and
    its conditional mean recovers the value hidden in the recording."""
    from vfcore.diagnose.extensions import get

    prior = Prior.default(fixed={n: getattr(TABLE3, n) for n in PARAM_NAMES if n != "E_cover"})
    rng = np.random.default_rng(5)
    hr0 = np.asarray(base_run.gaw_hr)
    y = observe_extended(name, hr0, FPS, phi)[55::HR_OVERSAMPLE][:240] + 0.5 * rng.standard_normal(240)
    pb = Problem(y, FPS, prior, config=CFG)
    ev = ExtendedEvaluator(pb, name, integrate=True)
    assert ev.prior.names == ("E_cover",)
    out = ev(np.array([[TABLE3.E_cover]]))
    ((pname, (lo, hi)),) = get(name).bounds().items()
    grid = lo + (np.arange(n_dense) + 0.5) * (hi - lo) / n_dense
    max_lag, n_cmp = pb.window
    lls = []
    for v in grid:
        hr = observe_extended(name, hr0, FPS, {pname: v})
        seg, _, _ = align(
            hr[::HR_OVERSAMPLE],
            pb.obs_gaw,
            FPS,
            (max_lag, n_cmp),
            sim_hr=hr,
            oversample=HR_OVERSAMPLE,
            method=pb.alignment,
        )
        lls.append(gaussian_loglik(seg, pb.obs_compared, pb.sigma_e))
    want = float(logsumexp(lls) - math.log(n_dense))
    assert abs(out.loglik[0] - want) < 0.05, (out.loglik[0], want)
    assert abs(out.extra[0, 0] - phi[pname]) < 3 * out.extra[0, 1] + 1e-3


def test_integrated_prior_keeps_only_what_needs_a_simulation():
    base = Prior.default(fixed={n: getattr(TABLE3, n) for n in PARAM_NAMES if n not in ("E_cover", "p_sub")})
    assert ExtendedPrior(bounds={}, base=base, extension="lr_stiffness", integrate=True).names == (
        "E_cover",
        "p_sub",
        "log2_lr_Q",
    )
    # the zipper's delay shape is sampled with the material parameters, its lag and taper integrated
    assert ExtendedPrior(bounds={}, base=base, extension="zipper", integrate=True).names == (
        "E_cover",
        "p_sub",
        "ap_power",
    )
    assert ExtendedPrior(bounds={}, base=base, extension="sep_ratio", integrate=True).names == (
        "E_cover",
        "p_sub",
        "sep_ratio",
    )


def test_delayed_slices_equal_interpolation_with_held_ends():
    from vfcore.diagnose.observers import delayed_copy

    rng = np.random.default_rng(2)
    y = rng.standard_normal(500)
    t = np.arange(y.size, dtype=float)
    pad = 40
    yp = np.concatenate([np.full(pad, y[0]), y, np.full(pad, y[-1])])
    for d in (0.0, 3.25, -7.5, 37.9, -38.0, 12.0, 45.5, -120.0):
        np.testing.assert_allclose(delayed_copy(yp, pad, y.size, d), np.interp(t - d, t, y), atol=1e-12)


@pytest.mark.parametrize("lag", [0.0, 0.07])
def test_null_drop_rejects_a_null_between_two_modes(base_run, lag):
    """Two folds of equal stiffness, the right one lagging by ``lag`` cycles: its sign is not
    identified (swapping the folds maps +lag to -lag), so the integrated lag's conditional mean
    is ~0 within its sd whatever the lag. The null drop (log-likelihood at the best lag minus at
    lag 0) tells the two apart: hundreds of nats for a real lag, ~0 without one."""
    from vfcore.diagnose.fit import pair_observer
    from vfcore.diagnose.rank import null_consistent

    prior = Prior.default(fixed={n: getattr(TABLE3, n) for n in PARAM_NAMES if n != "E_cover"})
    rng = np.random.default_rng(11)
    hr0 = np.asarray(base_run.gaw_hr)
    y = pair_observer(hr0, hr0, FPS)(lag)[55::HR_OVERSAMPLE][:240] + 0.3 * rng.standard_normal(240)
    pb = Problem(y, FPS, prior, config=CFG)
    ev = ExtendedEvaluator(pb, "lr_stiffness", integrate=True)
    out = ev(np.array([[TABLE3.E_cover, 0.0]]))
    assert out.ok[0]
    m, s, drop = out.extra[0]
    if lag:
        assert abs(m) < 2 * s and s > 0.5 * lag  # the mean +- sd test cannot see it
        assert drop > 50.0
        assert not null_consistent(("log2_lr_Q", "lr_lag"), [0.0, m], [0.02, s], "lr_stiffness", drops={"lr_lag": drop})
    else:
        assert 0.0 <= drop < 2.0
        assert null_consistent(("log2_lr_Q", "lr_lag"), [0.0, m], [0.02, s], "lr_stiffness", drops={"lr_lag": drop})


def test_integrated_membranous_chink_recovers_its_area_and_fraction(base_run):
    """The leak entry's two parameters integrated out of one simulation: the conditional means
    recover a hidden chink (1.2 mm^2, hidden where the GAW exceeds 1.2 / 0.3 = 4 mm^2), and the
    integrated log-likelihood equals the average over a dense grid of the prior box."""
    prior = Prior.default(fixed={n: getattr(TABLE3, n) for n in PARAM_NAMES if n != "E_cover"})
    rng = np.random.default_rng(8)
    hr0 = np.asarray(base_run.gaw_hr)
    phi = {"leak_mm2": 1.2, "chink_fraction": 0.3}
    y = observe_extended("leak", hr0, FPS, phi)[55::HR_OVERSAMPLE][:240] + 0.5 * rng.standard_normal(240)
    pb = Problem(y, FPS, prior, config=CFG)
    ev = ExtendedEvaluator(pb, "leak", integrate=True)
    assert ev.prior.names == ("E_cover",) and ev.integrated == ("leak_mm2", "chink_fraction")
    out = ev(np.array([[TABLE3.E_cover]]))
    for j, name in enumerate(ev.integrated):
        mean, sd = out.extra[0, 2 * j], out.extra[0, 2 * j + 1]
        assert abs(mean - phi[name]) < 3 * sd + 0.02 and sd < 0.2, (name, mean, sd)
    max_lag, n_cmp = pb.window

    def ll(a, f):
        hr = observe_extended("leak", hr0, FPS, {"leak_mm2": a, "chink_fraction": f})
        seg, _, _ = align(
            hr[::HR_OVERSAMPLE],
            pb.obs_gaw,
            FPS,
            (max_lag, n_cmp),
            sim_hr=hr,
            oversample=HR_OVERSAMPLE,
            method=pb.alignment,
        )
        return gaussian_loglik(seg, pb.obs_compared, pb.sigma_e)

    n_a, n_f = 240, 80  # the whole prior box [0, 3] x [0, 1]
    grid = [ll((i + 0.5) * 3.0 / n_a, (k + 0.5) / n_f) for i in range(n_a) for k in range(n_f)]
    want = float(logsumexp(grid) - math.log(n_a * n_f))
    assert abs(out.loglik[0] - want) < 0.1, (out.loglik[0], want)
