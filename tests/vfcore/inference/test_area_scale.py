"""Unknown area scale (uncalibrated px/mm): k integrated out of the likelihood in closed form
(vfcore.inference.likelihood; :ref:`inference-scale-unknown-area-scale`)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from vfcore.inference import Prior
from vfcore.inference.likelihood import (
    gaussian_loglik,
    marginal_gaussian_loglik,
    sample_area_scale,
    scaled_gaussian_loglik,
    scaled_marginal_gaussian_loglik,
)
from vfcore.inference.problem import Problem, validate_area_scale

FPS = 4000.0


def _pair(n=240, k=1.7, sd=0.5, seed=0):
    """A half-rectified 150 Hz pulse train (mm^2) and a recording of it at area scale ``k`` plus noise."""
    t = np.arange(n) / FPS
    seg = 5.0 * np.maximum(np.sin(2 * math.pi * 150.0 * t + 0.3), 0.0)
    return seg, k * seg + sd * np.random.default_rng(seed).standard_normal(n)


def _by_quadrature(single, seg, obs, k_lo, k_hi, ref):
    """log of the integral over k of exp(single(k seg)) / (k_hi - k_lo), scaled by exp(-ref)."""
    k_hat = float(obs @ seg / (seg @ seg))
    pts = [min(max(k_hat, k_lo), k_hi)]
    pts = pts if k_lo < pts[0] < k_hi else None
    v, _ = quad(lambda k: math.exp(single(k * seg) - ref), k_lo, k_hi, points=pts, epsabs=0.0, epsrel=1e-13, limit=400)
    return ref + math.log(v) - math.log(k_hi - k_lo)


CASES = [  # (k_lo, k_hi, noise sd, sigma bounds of the marginal noise)
    (0.25, 4.0, 0.5, (0.01, 100.0)),  # k_hat deep inside: the closed form alone
    (1.0, 1.69, 0.5, (0.01, 100.0)),  # the truth just beyond k_hi: the box cuts k's conditional
    (1.7, 3.0, 1.5, (0.01, 100.0)),  # k_hat at k_lo
    (0.2, 0.5, 0.5, (0.01, 100.0)),  # k_hat far outside the box
    (1.0, 2.0, 0.5, (0.45, 0.6)),  # a narrow noise prior: both truncations at once
    (1.65, 1.75, 2.0, (0.01, 100.0)),  # a box narrower than k's spread
]


@pytest.mark.parametrize("k_lo, k_hi, sd, sb", CASES)
def test_fixed_noise_marginal_equals_quadrature_over_k(k_lo, k_hi, sd, sb):
    seg, obs = _pair(sd=sd)
    a = scaled_gaussian_loglik(seg, obs, sd, k_lo, k_hi)
    b = _by_quadrature(lambda s: gaussian_loglik(s, obs, sd), seg, obs, k_lo, k_hi, a)
    assert abs(a - b) <= 1e-8 * max(1.0, abs(b)) and abs(a - b) < 1e-8 * 100


@pytest.mark.parametrize("k_lo, k_hi, sd, sb", CASES)
def test_unknown_noise_marginal_equals_quadrature_over_k(k_lo, k_hi, sd, sb):
    seg, obs = _pair(sd=sd)
    a = scaled_marginal_gaussian_loglik(seg, obs, *sb, k_lo, k_hi)
    b = _by_quadrature(lambda s: marginal_gaussian_loglik(s, obs, *sb), seg, obs, k_lo, k_hi, a)
    assert abs(a - b) <= 1e-8  # |log L_a - log L_q| <= 1e-8: the likelihoods agree to 1e-8 relative


def test_a_narrow_box_gives_the_likelihood_at_that_scale():
    seg, obs = _pair()
    k0, h = 1.6, 1e-7
    narrow = scaled_gaussian_loglik(seg, obs, 0.5, k0 - h, k0 + h)
    assert narrow == pytest.approx(gaussian_loglik(k0 * seg, obs, 0.5), abs=1e-6)


def _problem(**kw):
    seg, obs = _pair(n=600)
    prior = Prior(
        bounds={"p_sub": (700.0, 1300.0)},
        fixed={"E_body": 12.15, "E_cover": 636.2, "E_lig": 1.808, "rho": 1051.0, "eta": 3.079, "x0": 8.4},
    )
    return Problem(obs, FPS, prior, sigma_e=0.5, **kw)


@pytest.mark.parametrize("noise", ["fixed", "marginal"])
def test_calibrated_problems_score_exactly_as_eq15(noise):
    """area_scale=None leaves the likelihood bit for bit what it is without the option."""
    pb = _problem(noise=noise)
    assert pb.area_scale is None
    rng = np.random.default_rng(1)
    for _ in range(5):
        seg = pb.obs_compared + rng.normal(size=pb.n_compare)
        want = (
            marginal_gaussian_loglik(seg, pb.obs_compared, *pb.sigma_bounds)
            if noise == "marginal"
            else gaussian_loglik(seg, pb.obs_compared, pb.sigma_e)
        )
        assert pb.loglik(seg) == want
        r = (seg - pb.obs_compared) / pb.sigma_e
        if noise == "fixed":  # Eq. 15 written out
            assert want == float(-0.5 * np.dot(r, r) - r.size * (math.log(pb.sigma_e) + 0.5 * math.log(2 * math.pi)))


@pytest.mark.parametrize("noise", ["fixed", "marginal"])
def test_the_area_scale_round_trips_and_is_used(noise):
    pb = _problem(noise=noise, area_scale=(0.25, 4.0))
    back = Problem.from_dict(pb.to_dict())
    assert back.area_scale == (0.25, 4.0) and Problem.from_dict(_problem().to_dict()).area_scale is None
    seg = pb.obs_compared / 1.7
    assert pb.loglik(seg) > _problem(noise=noise).loglik(seg) + 100.0


@pytest.mark.parametrize("bad", [(1.0,), (0.0, 2.0), (2.0, 1.0), (1.0, math.inf), ("a", 2), "0.5:2"])
def test_bad_area_scales_are_one_line_errors(bad):
    with pytest.raises(ValueError, match="area_scale"):
        validate_area_scale(bad)


@pytest.mark.parametrize("noise", ["fixed", "marginal"])
def test_the_conditional_draws_of_k_match_its_posterior(noise):
    """Draws of k given a segment against the posterior density by quadrature: mean and sd."""
    seg, obs = _pair(sd=1.0)
    box, sb = (1.6, 1.75), (0.01, 100.0)
    rng = np.random.default_rng(5)
    kw = {"sigma": 1.0} if noise == "fixed" else {"sigma_bounds": sb}
    ks = np.array([sample_area_scale(seg, obs, rng, box, **kw) for _ in range(4000)])
    one = (
        (lambda s: gaussian_loglik(s, obs, 1.0))
        if noise == "fixed"
        else (lambda s: marginal_gaussian_loglik(s, obs, *sb))
    )
    ref = one(1.7 * seg)
    z = quad(lambda k: math.exp(one(k * seg) - ref), *box, epsrel=1e-10)[0]
    m1 = quad(lambda k: k * math.exp(one(k * seg) - ref), *box, epsrel=1e-10)[0] / z
    m2 = quad(lambda k: k * k * math.exp(one(k * seg) - ref), *box, epsrel=1e-10)[0] / z
    sd = math.sqrt(m2 - m1 * m1)
    assert np.all((ks >= box[0]) & (ks <= box[1]))
    assert abs(ks.mean() - m1) < 4 * sd / math.sqrt(ks.size)
    assert ks.std() == pytest.approx(sd, rel=0.06)


# ---------------------------------------------------------------------------- the reach check
def test_an_uncalibrated_recording_is_not_outside_for_its_area_only_for_its_f0(monkeypatch, tmp_path):
    """Peak areas 10-50 mm^2 in the ensemble: a recording of 200 mm^2 is outside when calibrated, inside
    with k in [1, 16] (true 12.5-200 mm^2); an f0 beyond the reach stays outside whatever the scale."""
    import sys
    from pathlib import Path

    monkeypatch.setenv("VFINFER_CACHE_DIR", str(tmp_path / "cache"))
    sys.path.insert(0, str(Path(__file__).parent))
    from test_reach import rec_at, synthetic  # the hand-made ensemble of the reach tests

    from vfcore.inference import reach as rc

    ens = synthetic()
    big = rec_at(ens, max_area_mm2=200.0)
    assert rc.check_reach(big, ens).verdict == "outside"
    v = rc.check_reach(big, ens, area_scale=(1.0, 16.0))
    assert v.verdict == "inside" and v.measures["max_area_mm2"]["verdict"] == "inside", v.message
    v = rc.check_reach(big, ens, area_scale=(1.0, 1.2))
    assert v.verdict == "outside" and "a true 167-200 mm^2 for an area scale in [1, 1.2]" in v.message
    assert "--uncalibrated" in v.message
    v = rc.check_reach(rec_at(ens, f0_hz=200.0, max_area_mm2=200.0), ens, area_scale=(1.0, 16.0))
    assert v.verdict == "outside" and v.measures["max_area_mm2"]["verdict"] == "inside"
    assert v.measures["f0_hz"]["verdict"] == "outside"


# ---------------------------------------------------------------------------- an FE twin at k = 1.7
@pytest.mark.slow
def test_an_fe_twin_recorded_at_area_scale_1p7_recovers_k_and_the_parameters():
    """The coarse-mesh twin of test_twin_fe (E_body, E_cover free in Table 2, the rest at Table 3, seed 7) recorded
    with its areas 1.7 times too large plus N(0, 1 mm^2) noise, fitted with k free on [0.25, 4] (SMC, 60
    particles, about 1,600 simulations, 1 min on one core): k = 1.7 inside its 90 % interval; the parameters
    recovered as test_twin_fe asks of the calibrated twin (the truth inside the joint 99 % region, every |z| < 3,
    and the posterior mean fitting at least as well as the truth). Per-parameter 90 % intervals of one twin
    are not asked for: an exact posterior misses them for 10 % of noise draws each (with this seed both
    parameters sit 1.6 sd from the mean, along their correlation); coverage is a property of many twins."""
    from vfcore.config import SimConfig
    from vfcore.inference import make_twin, smc
    from vfcore.inference.problem import evaluate
    from vfcore.params import PARAM_NAMES, TABLE3

    free = ("E_body", "E_cover")
    prior = Prior.default(fixed={n: getattr(TABLE3, n) for n in PARAM_NAMES if n not in free})
    cfg = SimConfig(mesh="coarse", dt=1e-4, duration=0.45, discard=0.25)
    tw = make_twin(prior, cfg, seed=7, sigma_e=1.0, n_obs=300)
    y = 1.7 * tw.clean_gaw + np.random.default_rng(11).standard_normal(tw.clean_gaw.size)
    pb = Problem(y, cfg.fps, prior, sigma_e=1.0, config=cfg, area_scale=(0.25, 4.0))
    post = smc(pb, n_particles=60, seed=7, ess_fraction=0.5, min_moves=2, max_moves=4)
    q = post.quantile([0.05, 0.95])
    pred = post.resampled_predictive()
    rng = np.random.default_rng(0)
    ks = np.array([pb.sample_area_scale(np.asarray(g, dtype=float), rng) for g in pred.gaw])
    kq = np.quantile(ks, [0.05, 0.95])
    print(post.format_summary(), "\ntruth", tw.truth_dict, "k 90 %", kq, "mean", ks.mean(), "q", q)
    assert kq[0] <= 1.7 <= kq[1], kq
    d = post.mean - tw.truth
    m2 = float(d @ np.linalg.solve(post.cov, d))  # squared Mahalanobis distance of the truth
    assert m2 < 9.21 and np.all(np.abs(d) / post.sd < 3.0), (m2, q, tw.truth)
    ll = evaluate(np.vstack([tw.truth, post.mean]), pb).loglik
    assert ll[1] > ll[0] - 2.0, ll


def test_recorded_gaws_scale_each_draw_by_its_clipped_least_squares_k():
    """What the diagnosis compares with an uncalibrated recording: each predicted GAW times its own
    least-squares scale, clipped to the area-scale box; unchanged without an area scale."""
    import numpy as np

    from vfcore.inference.posterior import Posterior
    from vfcore.inference.problem import Evaluation

    t = np.linspace(0.0, 1.0, 50)
    a = np.vstack([np.sin(np.pi * t) ** 2, 2.0 * np.sin(np.pi * t) ** 2, np.sin(np.pi * t) ** 2])
    y = 0.5 * a[0]
    ev = Evaluation(loglik=np.zeros(3), ok=np.array([True, True, False]), gaw=a.astype(np.float32))
    post = Posterior(
        names=("E_body",),
        samples=np.zeros((3, 1)),
        log_weights=np.log(np.full(3, 1 / 3)),
        resampled=np.arange(3),
        ess=3.0,
        pareto_k=0.0,
        log_evidence=0.0,
        log_evidence_se=0.0,
        n_simulations=3,
        predictive=ev,
        obs_gaw=y,
        fps=2000.0,
    )
    assert np.array_equal(post.recorded_gaws(), a[:2].astype(np.float32).astype(float))
    post.area_scale = (0.3, 4.0)
    g = post.recorded_gaws()
    assert g.shape == (2, 50)
    np.testing.assert_allclose(g[0], y, rtol=1e-6)  # k = 0.5, inside the box
    np.testing.assert_allclose(g[1], 0.3 * 2.0 * a[0], rtol=1e-6)  # k = 0.25, clipped to 0.3
