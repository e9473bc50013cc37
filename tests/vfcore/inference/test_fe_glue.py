"""evaluate / Problem / products / export on a cheap analytic stand-in for the FE model."""

import math

import numpy as np
import pytest
from inf_helpers import FakeSimulator
from scipy import stats

from vfcore.config import SimConfig
from vfcore.inference import (
    DegenerateEnsembleWarning,
    Evaluation,
    Posterior,
    Prior,
    Problem,
    ProblemEvaluator,
    compare,
    ensemble_size_study,
    evaluate,
    flow_contact_table,
    gaussian_loglik,
    importance_sample,
    numerics_study,
    plot_marginals,
    plot_predictive,
    predictive_bands,
    smc,
)


@pytest.fixture(scope="module")
def problem():
    sim = FakeSimulator()
    prior = Prior({"E_body": (9.0, 15.0), "p_sub": (400.0, 1800.0), "E_lig": (0.5, 3.0)})
    assert prior.names == ("E_body", "E_lig", "p_sub")
    truth = prior.to_params(np.array([12.5, 1.5, 1000.0]))
    cfg = SimConfig(mesh="coarse", dt=1e-4)
    r = sim(truth, cfg)
    y = r.gaw[:500] + np.random.default_rng(0).standard_normal(500)
    return Problem(y, 2000.0, prior, sigma_e=1.0, config=cfg)


def test_gaussian_loglik():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=50), rng.normal(size=50)
    assert gaussian_loglik(a, b, 0.7) == pytest.approx(np.sum(stats.norm.logpdf(b, loc=a, scale=0.7)))
    assert gaussian_loglik(np.r_[a[:-1], np.nan], b, 1.0) == -math.inf
    with pytest.raises(ValueError):
        gaussian_loglik(a[:3], b, 1.0)


def test_evaluate_counts_failures(problem):
    th = np.array(
        [
            [12.5, 1.5, 1000.0],  # truth (E_body, E_lig, p_sub)
            [12.5, 1.5, 420.0],  # ok=False
            [12.5, 2.95, 1000.0],  # raises
            [10.0, 1.0, 1500.0],
        ]
    )
    ev = evaluate(th, problem, simulate_fn=FakeSimulator())
    assert list(ev.ok) == [True, False, False, True]
    assert ev.loglik[1] == -np.inf and ev.loglik[2] == -np.inf and ev.n_failed == 2
    assert ev.gaw.dtype == np.float32 and ev.gaw.shape == (4, problem.n_compare)
    assert np.all(np.isnan(ev.gaw[1])) and np.isfinite(ev.gaw[0]).all()
    assert ev.loglik[0] > ev.loglik[3]
    # residual at the truth is pure noise: loglik ~ -n/2 (1 + log 2 pi)
    assert ev.loglik[0] == pytest.approx(-problem.n_compare / 2 * (1 + math.log(2 * math.pi)), rel=0.1)
    assert any("synthetic divergence" in m for m in ev.messages)
    assert any(m.startswith("2: FloatingPointError") for m in ev.messages)
    assert ev.mean_flow[0] > 0 and ev.max_contact[0] >= ev.mean_contact[0]
    # concat re-numbers messages
    both = Evaluation.concat([ev, ev])
    assert len(both) == 8 and any(m.startswith("6: ") for m in both.messages)


@pytest.fixture(scope="module")
def fitted(problem):
    ev = ProblemEvaluator(problem, FakeSimulator())
    with pytest.warns(DegenerateEnsembleWarning):  # the likelihood is far too sharp for 3000 prior draws
        post_is = importance_sample(_Wrapped(problem, ev), problem.prior, n=3000, seed=1, chunk_size=500)
    post_smc = smc(_Wrapped(problem, ev), problem.prior, n_particles=150, seed=1)
    return post_is, post_smc


class _Wrapped:
    """Callable target returning full Evaluations (as a worker would), plus obs for plots."""

    def __init__(self, problem, ev):
        self.problem, self.ev = problem, ev

    def __call__(self, th):
        return self.ev(th)


def test_twin_with_fake_model(problem, fitted):
    post_is, post_smc = fitted
    assert post_is.ess < 100 and post_is.warnings and post_is.n_failed > 0
    for post in (post_smc,):
        assert post.predictive is not None
        for name, true in (("E_body", 12.5), ("p_sub", 1000.0)):  # E_lig does not enter the fake model
            j = post.names.index(name)
            assert abs(post.mean[j] - true) < 2 * post.sd[j] + 1e-9, post.format_summary()
    assert post_smc.n_simulations == 150 + sum(g["n_simulations"] for g in post_smc.info["generations"])


def test_products(problem, fitted, tmp_path):
    for post in fitted:
        post.obs_gaw, post.fps = problem.obs_compared, problem.fps
        b = predictive_bands(post, level=0.9)
        assert b["mean"].shape == (problem.n_compare,) and np.all(b["lo"] <= b["hi"])
        bn = predictive_bands(post, level=0.9, sigma_e=1.0)
        assert np.all(bn["hi"] - bn["lo"] >= b["hi"] - b["lo"] - 1e-9)
        rows = flow_contact_table(post)
        assert [r["quantity"] for r in rows] == [
            "flow rate Q",
            "contact impulse per cycle",
            "pressure in contact",
            "mean nodal peak contact pressure (not converged)",
            "max nodal contact pressure (not converged)",
        ]
        assert rows[0]["mean"] > 0 and rows[0]["unit"] == "mL/s"
        assert plot_predictive(post, tmp_path / f"pp_{post.method}.png").stat().st_size > 1000
        assert plot_marginals(post, tmp_path / f"m_{post.method}.png", truth={"E_body": 12.5}).exists()


def test_compare_matches_scipy(fitted):
    a, b = fitted
    rows = compare(a, b)
    assert [r["name"] for r in rows] == list(a.names)
    for r in rows:
        j = a.names.index(r["name"])
        xa, xb = a.resampled_samples[:, j], b.resampled_samples[:, j]
        t = stats.ttest_ind(xa, xb, equal_var=False)
        assert r["t"] == pytest.approx(t.statistic) and r["p"] == pytest.approx(t.pvalue)
        # Welch by hand
        se = math.sqrt(xa.var(ddof=1) / xa.size + xb.var(ddof=1) / xb.size)
        assert r["t"] == pytest.approx((xa.mean() - xb.mean()) / se)
    with pytest.raises(ValueError):
        compare(a, b, names=["rho"])


def test_export_roundtrip(problem, fitted, tmp_path):
    from vfcore.inference.problem import model_record

    for post in fitted:
        assert post.model is None  # a callable target: the model it ran is unknown
        post.obs_gaw, post.fps, post.model = problem.obs_compared, problem.fps, model_record(problem)
        p = post.to_csv(tmp_path / "s.csv")
        q = Posterior.from_csv(p)
        assert q.names == post.names and q.model == post.model and q.model["dt"] == 1e-4
        assert np.array_equal(q.samples, post.samples) and np.array_equal(q.log_weights, post.log_weights)
        assert np.array_equal(np.sort(q.resampled), np.sort(post.resampled))
        assert q.log_evidence == post.log_evidence and q.n_simulations == post.n_simulations
        assert np.allclose(q.mean, post.mean) and np.allclose(q.sd, post.sd)
        nc = post.to_netcdf(tmp_path / "s.nc")
        r = Posterior.from_netcdf(nc)
        assert np.array_equal(r.samples, post.samples) and np.array_equal(r.log_weights, post.log_weights)
        assert np.array_equal(r.resampled, post.resampled) and r.warnings == post.warnings
        assert r.ess == post.ess and r.method == post.method
        assert r.model == post.model and not problem.config.differences(r.model)
        rp0, rp1 = post.resampled_predictive(), r.resampled_predictive()
        assert np.array_equal(rp0.gaw, rp1.gaw, equal_nan=True)
        assert np.array_equal(r.obs_gaw, post.obs_gaw)
        idata = post.to_inference_data()
        assert idata.posterior[post.names[0]].shape == (1, post.resampled.size)


def test_sensitivity(problem, fitted, tmp_path):
    post_is, _ = fitted
    rows = ensemble_size_study(
        post_is,
        [100, 300, 1000, 3000],
        truth={"E_body": 12.5, "p_sub": 1000.0, "E_lig": 1.5},
        n_repeats=3,
        figure_path=tmp_path / "fig7.png",
    )
    assert {r["n"] for r in rows} == {100, 300, 1000, 3000} and (tmp_path / "fig7.png").exists()
    assert len(rows) == 4 * 3
    sim = FakeSimulator()

    def sampler(p):
        return smc(ProblemEvaluator(p, sim), p.prior, n_particles=60, seed=0)

    cfgs = {"dt=1e-4": problem.config, "mesh=medium": problem.config.replace(mesh="medium")}
    rows = numerics_study(
        problem, cfgs, sampler, truth={"E_body": 12.5, "p_sub": 1000.0, "E_lig": 1.5}, figure_path=tmp_path / "fig8.png"
    )
    assert len(rows) == 2 * 3 and (tmp_path / "fig8.png").exists()
    with pytest.raises(ValueError):
        ensemble_size_study(fitted[1], [10])


def test_make_twin_with_fake_model():
    from vfcore.inference import make_twin

    prior = Prior({"E_body": (9.0, 15.0), "p_sub": (400.0, 1800.0)})
    tw = make_twin(prior, SimConfig(mesh="coarse"), seed=4, simulate_fn=FakeSimulator())
    tw2 = make_twin(prior, SimConfig(mesh="coarse"), seed=4, simulate_fn=FakeSimulator())
    assert np.array_equal(tw.problem.obs_gaw, tw2.problem.obs_gaw) and np.array_equal(tw.truth, tw2.truth)
    assert tw.problem.obs_gaw.size == 400 and np.all(prior.contains(tw.truth[None]))
    resid = tw.problem.obs_gaw - tw.clean_gaw
    assert 0.8 < resid.std() < 1.2
    assert set(tw.truth_dict) == {"E_body", "p_sub"}
