"""Measured parameters (Problem(measurements={name: (mean, sd)})): an independent Gaussian term added to
the GAW log-likelihood of every draw, in every path that scores a draw; validated before any simulation."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest
from inf_helpers import FakeSimulator
from scipy import stats
from toy_model import ToyEvaluator, toy_observation

from vfcore.config import SimConfig
from vfcore.inference import Prior, Problem, ProblemEvaluator, evaluate, importance_sample
from vfcore.inference.problem import aligned_loglik, validate_measurements
from vfcore.params import TABLE3

FIXED = {"E_body": 12.15, "E_lig": 1.808, "rho": 1051.0, "eta": 3.079, "x0": 8.4}
CFG = SimConfig(duration=0.35, discard=0.2)


def _toy_problem(measurements=None, noise="fixed", free=("E_cover", "p_sub")):
    bounds = {"E_cover": (450.0, 850.0), "p_sub": (700.0, 1300.0)}
    fixed = {**FIXED, **{n: getattr(TABLE3, n) for n in bounds if n not in free}}
    prior = Prior(bounds={n: bounds[n] for n in free}, fixed=fixed)
    y = np.asarray(toy_observation({"p_sub": 989.9}, noise=3.0, seed=1))
    return Problem(y, 4000.0, prior, sigma_e=3.0, config=CFG, noise=noise, measurements=measurements or {})


def test_the_term_is_the_gaussian_log_density():
    meas = {"p_sub": (1000.0, 50.0), "E_cover": (600.0, 30.0)}
    pb = _toy_problem(meas)
    p = TABLE3.replace(E_cover=655.0, p_sub=1111.0)
    hand = (
        -0.5 * ((1111.0 - 1000.0) / 50.0) ** 2
        - math.log(50.0 * math.sqrt(2 * math.pi))
        - 0.5 * ((655.0 - 600.0) / 30.0) ** 2
        - math.log(30.0 * math.sqrt(2 * math.pi))
    )
    assert pb.measurement_loglik(p) == pytest.approx(hand, abs=1e-12)
    assert hand == pytest.approx(stats.norm.logpdf(1000.0, 1111.0, 50.0) + stats.norm.logpdf(600.0, 655.0, 30.0))
    assert pb.measurement_loglik(p.as_dict()) == pb.measurement_loglik(p.as_array()) == pb.measurement_loglik(p)
    assert _toy_problem().measurement_loglik(p) == 0.0
    # Problem.loglik adds it when given the draw's parameters, for either noise model
    seg = pb.obs_compared + 0.5
    for noise in ("fixed", "marginal"):
        with_m, without = _toy_problem(meas, noise), _toy_problem(None, noise)
        assert with_m.loglik(seg, p) - without.loglik(seg) == pytest.approx(hand, abs=1e-9)
        assert with_m.loglik(seg) == without.loglik(seg)
    assert pb.loglik(seg + np.nan, p) == -math.inf


def test_every_scoring_path_adds_the_term():
    """evaluate (with failures: they stay -inf), ProblemEvaluator, the worker's toy evaluator and
    aligned_loglik all add exactly log N(mean | theta, sd^2) per draw."""
    sim = FakeSimulator()
    prior = Prior({"E_body": (9.0, 15.0), "p_sub": (400.0, 1800.0), "E_lig": (0.5, 3.0)})
    cfg = SimConfig(mesh="coarse", dt=1e-4)
    r = sim(prior.to_params(np.array([12.5, 1.5, 1000.0])), cfg)
    y = r.gaw[:500] + np.random.default_rng(0).standard_normal(500)
    plain = Problem(y, 2000.0, prior, sigma_e=1.0, config=cfg)
    meas = Problem(y, 2000.0, prior, sigma_e=1.0, config=cfg, measurements={"p_sub": (950.0, 40.0)})
    th = np.array([[12.5, 1.5, 1000.0], [12.0, 1.2, 900.0], [12.5, 1.5, 420.0], [12.5, 2.95, 1000.0]])
    a, b = evaluate(th, plain, simulate_fn=sim), evaluate(th, meas, simulate_fn=sim)
    assert list(b.ok) == [True, True, False, False]
    expect = stats.norm.logpdf(950.0, th[:2, 2], 40.0)
    np.testing.assert_allclose(b.loglik[:2] - a.loglik[:2], expect, rtol=0, atol=1e-9)
    assert np.all(np.isneginf(b.loglik[2:]))
    np.testing.assert_array_equal(ProblemEvaluator(meas, sim)(th).loglik, b.loglik)
    hr = np.repeat(r.gaw, 10)[: 10 * (r.gaw.size - 1) + 1]
    assert aligned_loglik(hr, meas, r.params)[0] - aligned_loglik(hr, plain)[0] == pytest.approx(
        stats.norm.logpdf(950.0, 1000.0, 40.0), abs=1e-9
    )
    # the worker's analytic stand-in
    tp, tm = _toy_problem(), _toy_problem({"p_sub": (1020.0, 15.0)})
    rows = np.array([[600.0, 900.0], [700.0, 1100.0]])
    np.testing.assert_allclose(
        ToyEvaluator(tm)(rows).loglik - ToyEvaluator(tp)(rows).loglik,
        stats.norm.logpdf(1020.0, rows[:, 1], 15.0),
        rtol=0,
        atol=1e-9,
    )


def test_a_measurement_multiplies_the_posterior():
    """Importance sampling with p_sub measured as 1020 +- 15 Pa gives the posterior of (GAW likelihood on
    a grid) x (that Gaussian), not the GAW-only one (883 +- 63 Pa on this toy recording)."""
    m, sd = 1020.0, 15.0
    pb = _toy_problem({"p_sub": (m, sd)}, free=("p_sub",))
    post = importance_sample(ToyEvaluator(pb), pb.prior, 2000, seed=1)
    grid = np.linspace(700.0, 1300.0, 1201)
    ll_gaw = ToyEvaluator(_toy_problem(free=("p_sub",)))(grid[:, None]).loglik

    def moments(ll):
        w = np.exp(ll - ll.max())
        w /= w.sum()
        mu = float(w @ grid)
        return mu, float(math.sqrt(w @ (grid - mu) ** 2))

    mu, s = moments(ll_gaw + stats.norm.logpdf(m, grid, sd))
    mu0, s0 = moments(ll_gaw)
    assert abs(mu - mu0) > 3 * s  # the two posteriors are told apart
    assert abs(post.mean[0] - mu) < 0.25 * s
    assert 0.8 < post.sd[0] / s < 1.2


def test_round_trip_and_pickle():
    pb = _toy_problem({"p_sub": (1000.0, 50.0)})
    d = pb.to_dict()
    assert d["measurements"] == {"p_sub": [1000.0, 50.0]}
    back = Problem.from_dict(d)
    assert back.measurements == {"p_sub": (1000.0, 50.0)}
    assert pickle.loads(pickle.dumps(pb)).measurements == pb.measurements
    assert Problem.from_dict({k: v for k, v in d.items() if k != "measurements"}).measurements == {}


@pytest.mark.parametrize(
    "bad, match",
    [
        ({"p_subglottal": (1000.0, 50.0)}, "unknown parameter 'p_subglottal'"),
        ({"p_sub": (1000.0, 0.0)}, "sd > 0"),
        ({"p_sub": (1000.0, -5.0)}, "sd > 0"),
        ({"p_sub": (math.nan, 5.0)}, "finite"),
        ({"p_sub": (1000.0, math.inf)}, "finite"),
        ({"p_sub": (1000.0,)}, "pair"),
        ({"p_sub": "1000:50"}, "pair"),
        ({"p_sub": ("a", 5.0)}, "pair"),
        ({"rho": (1051.0, 10.0)}, "rho: the parameter is fixed"),
        ([("p_sub", (1000.0, 50.0))], "mapping"),
    ],
)
def test_bad_measurements_raise_one_clear_line(bad, match):
    with pytest.raises(ValueError, match=match) as exc:
        _toy_problem(bad)
    assert "\n" not in str(exc.value)


def test_a_measurement_of_a_parameter_neither_estimated_nor_fixed_is_refused():
    prior = Prior(bounds={"p_sub": (700.0, 1300.0)})  # the rest at Table 3 values, not estimated
    with pytest.raises(ValueError, match="E_cover: the parameter is not estimated"):
        validate_measurements({"E_cover": (600.0, 10.0)}, prior)
    assert validate_measurements({"p_sub": [1000, 5]}, prior) == {"p_sub": (1000.0, 5.0)}
