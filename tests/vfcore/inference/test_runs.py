"""Independent SMC runs pooled (``vfcore.inference.runs``): the rule on hand-made runs whose answer is known,
and ``smc(runs=K)`` on the linear-Gaussian toy against its exact posterior."""

import math

import numpy as np
import pytest
from linear_gaussian import LinearGaussianToy
from scipy.special import logsumexp

from vfcore.inference import Evaluation, Posterior, Prior, pool_runs, run_seeds, smc


def _run(center, log_z, n, seed, peak=None):
    """A finished run about ``center``: its predictions' log-likelihood peaks at ``peak`` (default ``log_z``)."""
    rng = np.random.default_rng(seed)
    x = center + 0.1 * rng.standard_normal((n, 2))
    p = Posterior.from_weighted(
        ("a", "b"),
        x,
        np.zeros(n),
        rng=rng,
        log_evidence=log_z,
        log_evidence_se=0.3,
        n_simulations=10 * n,
        method="smc",
        check=False,
    )
    p.predictive = Evaluation(
        loglik=-((x - center) ** 2).sum(1) + (log_z if peak is None else peak), ok=np.ones(n, bool)
    )
    p.predictive_index = np.arange(n)
    return p


def test_a_run_whose_best_particle_is_far_below_the_best_runs_is_left_out():
    """The default rule reads each run's best particle: runs of one basin reach the same peak whatever their
    evidence estimates say; a run that missed the basin peaks lower."""
    a = _run(0.0, -100.0, 40, 1, peak=-50.0)
    b = _run(0.1, -130.0, 40, 2, peak=-50.5)  # same basin, evidence 30 nats lower by the sampler's luck
    c = _run(5.0, -99.0, 40, 3, peak=-58.0)  # another basin, 8 nats short at its peak
    post = pool_runs([a, b, c])
    assert [r["kept"] for r in post.info["runs"]] == [True, True, False]
    assert post.info["run_rule"] == "loglik" and post.info["run_gap"] == 3.0
    assert np.allclose(post.mean, 0.5 * (a.mean + b.mean))
    assert [r["best_loglik"] for r in post.info["runs"]] == pytest.approx([-50.0, -50.5, -58.0], abs=0.05)
    # the evidence rule, on the same runs, keeps a and c and drops b: the luck of the evidence decides
    ev = pool_runs([a, b, c], rule="evidence")
    assert [r["kept"] for r in ev.info["runs"]] == [True, False, True]


def test_a_run_far_below_the_best_evidence_is_left_out_and_the_rest_share_equally():
    a, b, c = _run(0.0, -100.0, 40, 1), _run(0.2, -103.0, 60, 2), _run(5.0, -110.0, 50, 3)
    post = pool_runs([a, b, c], rule="evidence")
    # c (10 nats below a) holds at most e^-5 of the mass: out; a and b share 1/2 each though b has 60 particles
    assert [r["kept"] for r in post.info["runs"]] == [True, True, False] and post.info["runs_kept"] == 2
    assert np.allclose(post.mean, 0.5 * a.mean + 0.5 * b.mean)
    assert post.samples.shape == (100, 2) and math.isclose(post.weights.sum(), 1.0)
    # the evidence is the mean of all runs' Z (each unbiased for Z), left-out runs included
    assert math.isclose(post.log_evidence, logsumexp([-100.0, -103.0, -110.0]) - math.log(3))
    assert post.n_simulations == a.n_simulations + b.n_simulations + c.n_simulations
    assert any(w.startswith("RUNS DISAGREE: 1 of 3") and "left out" in w for w in post.warnings)
    # every pooled draw's predictive row is its own run's
    pred = post.resampled_predictive()
    x = post.resampled_samples
    centre = np.where(post.resampled < 40, 0.0, 0.2)
    assert np.allclose(
        pred.loglik, -((x - centre[:, None]) ** 2).sum(1) + np.where(post.resampled < 40, -100.0, -103.0)
    )
    # a wider gap keeps c: three runs, equal shares
    wide = pool_runs([a, b, c], rule="evidence", gap=20.0)
    assert wide.info["runs_kept"] == 3 and np.allclose(wide.mean, (a.mean + b.mean + c.mean) / 3)


def test_pooling_refuses_what_cannot_be_pooled():
    a = _run(0.0, -100.0, 10, 1)
    with pytest.raises(ValueError, match="at least one run"):
        pool_runs([])
    with pytest.raises(ValueError, match="finite log evidence"):
        pool_runs([a, _run(0.0, float("nan"), 10, 2)])
    with pytest.raises(ValueError, match="gap"):
        pool_runs([a], gap=0.0)
    with pytest.raises(ValueError, match="rule must be one of"):
        pool_runs([a], rule="vote")
    blind = _run(0.0, -100.0, 10, 2)
    blind.predictive = None
    with pytest.raises(ValueError, match="best log-likelihood"):
        pool_runs([a, blind])
    with pytest.raises(ValueError, match="runs must be at least 1"):
        run_seeds(3, 0)


def test_smc_runs_are_independent_seeded_runs_pooled():
    prior = Prior.default(fixed={"rho": 1051.0, "eta": 3.0, "x0": 8.4, "p_sub": 900.0})
    toy = LinearGaussianToy(prior, n_obs=6, noise=0.05, seed=0)
    pooled = smc(toy, prior, n_particles=150, seed=3, runs=3)
    singles = [smc(toy, prior, n_particles=150, seed=s) for s in run_seeds(3, 3)]
    assert run_seeds(3, 3) == [3, 3 + 7919, 3 + 2 * 7919]
    assert [r["seed"] for r in pooled.info["runs"]] == run_seeds(3, 3)
    # the first run is the plain run of the same seed, bit for bit
    assert pooled.samples[:150].tobytes() == singles[0].samples.tobytes()
    assert pooled.n_simulations == sum(p.n_simulations for p in singles)
    # one unimodal posterior: every run kept, the pool matches the exact answer better than the runs' spread
    assert pooled.info["runs_kept"] == 3
    spread = np.std([p.mean for p in singles], axis=0, ddof=1)
    assert np.all(np.abs(pooled.mean - toy.mean) < 4 * spread / math.sqrt(3) + 1e-3 * np.abs(toy.mean))
    assert np.all(np.abs(pooled.sd / toy.sd - 1) < 0.25)
    again = smc(toy, prior, n_particles=150, seed=3, runs=3)
    assert again.samples.tobytes() == pooled.samples.tobytes() and again.log_evidence == pooled.log_evidence
