"""IS and SMC against the closed-form linear-Gaussian posterior and evidence.

Tolerances come from Monte Carlo standard errors: for self-normalised IS the delta-method
s.e. of a weighted mean, sqrt(sum w_i^2 (f_i - f_hat)^2); for SMC the spread over
independent seeded replications (Student-t bound). Fixed seeds keep the tests deterministic.
"""

import math
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from linear_gaussian import LinearGaussianToy
from scipy import stats

from vfcore.inference import Prior, SMCSampler, draw_prior, importance_sample, reduce_importance, smc

Z = 4.0  # standard errors allowed (two-sided p ~ 6e-5 per comparison)


@pytest.fixture(scope="module")
def prior2():
    return Prior({"E_body": (9.0, 15.0), "p_sub": (400.0, 1800.0)})


@pytest.fixture(scope="module")
def prior3():
    return Prior.default(fixed={"rho": 1051.0, "eta": 3.0, "x0": 8.4, "p_sub": 900.0})


def _is_se(post, f):
    """Delta-method s.e. of the self-normalised IS estimate of E[f]."""
    w = post.weights
    fhat = w @ f
    return math.sqrt(np.sum(w**2 * (f - fhat) ** 2))


def test_toy_is_exact(prior2):
    toy = LinearGaussianToy(prior2, n_obs=5, noise=0.08, seed=3)
    assert toy.truncation_mass < 1e-6
    post = importance_sample(toy, prior2, n=40000, seed=11, chunk_size=5000)
    assert post.ess > 200
    assert post.n_simulations == 40000 and post.n_failed == 0
    for j in range(2):
        x = post.samples[:, j]
        se_m = _is_se(post, x)
        assert abs(post.mean[j] - toy.mean[j]) < Z * se_m, (j, post.mean[j], toy.mean[j], se_m)
        v_true = toy.cov[j, j]
        se_v = _is_se(post, (x - post.mean[j]) ** 2)
        assert abs(post.sd[j] ** 2 - v_true) < Z * se_v + 1e-12
    # evidence within its own MC error
    assert abs(post.log_evidence - toy.log_evidence) < Z * post.log_evidence_se
    assert 0 < post.log_evidence_se < 0.2
    # 90% credible interval close to the Gaussian one
    lo, hi = post.credible_interval(0.9)
    g_lo = toy.mean - 1.6449 * toy.sd
    assert np.allclose(lo, g_lo, atol=0.25 * toy.sd.max())


@pytest.mark.parametrize("init_factor", [1, 4])
def test_toy_smc_exact(prior3, init_factor):
    """Posterior moments and log-evidence against the exact answers; with a 4x larger first
    population (resampled down to N after the first reweighting) too."""
    toy = LinearGaussianToy(prior3, n_obs=6, noise=0.05, seed=0)
    assert toy.truncation_mass < 1e-6
    R = 8
    means, variances, logz, sims = [], [], [], []
    for s in range(R):
        post = smc(toy, prior3, n_particles=300, seed=100 + s, init_factor=init_factor)
        means.append(post.mean)
        variances.append(post.sd**2)
        logz.append(post.log_evidence)
        sims.append(post.n_simulations)
    means, variances, logz = map(np.asarray, (means, variances, logz))
    t = stats.t.ppf(1 - 1e-4, R - 1)
    for arr, exact in ((means, toy.mean), (variances, np.diag(toy.cov))):
        se = arr.std(axis=0, ddof=1) / math.sqrt(R)
        assert np.all(np.abs(arr.mean(axis=0) - exact) < t * se + 1e-3 * np.abs(exact)), (arr.mean(0), exact, se)
    # log Z_hat is biased low by ~Var/2 (Jensen); Z_hat itself is unbiased
    v = logz.var(ddof=1)
    assert abs(logz.mean() + v / 2 - toy.log_evidence) < t * math.sqrt(v / R) + 0.02
    # and each run's own quoted s.e. is not wildly optimistic
    assert np.all(np.abs(logz - toy.log_evidence) < 6 * math.sqrt(v) + 0.1)
    # a fraction of the IS cost: the point of the adaptive sampler
    assert max(sims) < 8000 + 300 * (init_factor - 1)


def test_is_deterministic_and_map_independent(prior2):
    toy = LinearGaussianToy(prior2, seed=1)
    a = importance_sample(toy, prior2, n=3000, seed=5, chunk_size=100)
    with ThreadPoolExecutor(2) as ex:
        b = importance_sample(toy, prior2, n=3000, seed=5, chunk_size=777, map=ex.map)
    assert a.samples.tobytes() == b.samples.tobytes()
    assert a.log_weights.tobytes() == b.log_weights.tobytes()
    assert np.array_equal(a.resampled, b.resampled)
    assert a.log_evidence == b.log_evidence
    c = importance_sample(toy, prior2, n=3000, seed=6)
    assert not np.array_equal(a.samples, c.samples)


def test_chunked_reduce_equals_one_shot(prior2):
    toy = LinearGaussianToy(prior2, seed=1)
    th = draw_prior(prior2, 2000, 9)
    ll = np.concatenate([toy(c) for c in np.array_split(th, 7)])
    a = reduce_importance(th, ll, prior2.names, 9)
    b = importance_sample(toy, prior2, n=2000, seed=9)
    assert np.array_equal(a.mean, b.mean) and np.array_equal(a.resampled, b.resampled)


def test_smc_deterministic_and_map_independent(prior3):
    toy = LinearGaussianToy(prior3, seed=2)
    a = smc(toy, prior3, n_particles=120, seed=3, chunk_size=7)
    with ThreadPoolExecutor(2) as ex:
        b = smc(toy, prior3, n_particles=120, seed=3, chunk_size=50, map=ex.map)
    assert a.samples.tobytes() == b.samples.tobytes()
    assert a.log_evidence == b.log_evidence and a.n_simulations == b.n_simulations
    assert a.info["temperatures"] == b.info["temperatures"]
    assert a.info["temperatures"][-1] == 1.0
    assert all(np.diff(a.info["temperatures"]) > 0)


def test_smc_many_gives_each_run_as_alone(prior3):
    """Runs made together (one batch a round through the map) equal each run made alone, bit for bit, and
    go through the map in as many calls as the longest run's batches, not the sum of all runs'."""
    from vfcore.inference.smc import smc_many

    toy = LinearGaussianToy(prior3, seed=2)
    jobs = [(40, 3), (60, 8), (40, 11)]
    calls = []

    def counting(fn, parts):
        parts = list(parts)
        calls.append(sum(np.shape(p)[0] for p in parts))
        return map(fn, parts)

    finished = []
    posts = smc_many(toy, jobs, prior3, map=counting, chunk_size=1000, on_done=lambda i, p: finished.append(i))
    alone = [smc(toy, prior3, n_particles=n, seed=sd, chunk_size=7) for n, sd in jobs]
    for a, b in zip(posts, alone):
        assert a.samples.tobytes() == b.samples.tobytes() and a.resampled.tobytes() == b.resampled.tobytes()
        assert a.log_evidence == b.log_evidence and a.log_evidence_se == b.log_evidence_se
        assert a.n_simulations == b.n_simulations and a.info["temperatures"] == b.info["temperatures"]
    assert sorted(finished) == [0, 1, 2]
    assert sum(calls) == sum(int(p.n_simulations) for p in alone)
    # one batch for the first population, then one a move step (a step whose proposals all left the
    # prior asks for none)
    batches = [1 + sum(h["moves"] for h in p.info["generations"]) for p in alone]
    assert max(batches) <= len(calls) < sum(batches)
    with pytest.raises(ValueError, match="screen"):
        smc_many(toy, jobs, prior3, screen=toy)


def test_smc_ask_tell_and_failures(prior3):
    toy = LinearGaussianToy(prior3, seed=2)

    def failing(th):  # a tenth of parameter space "crashes"
        ll = toy(th)
        ll[th[:, 0] > 14.4] = -np.inf
        return ll

    s = SMCSampler(prior3, n_particles=100, seed=0)
    first = s.ask()
    assert s.ask() is first  # idempotent until tell
    n = 0
    while (th := s.ask()) is not None:
        s.tell(failing(th))
        n += th.shape[0]
    post = s.result()
    assert post.n_simulations == n and post.n_failed > 0
    assert np.all(post.samples[:, 0] <= 14.4)
    with pytest.raises(RuntimeError):
        s.tell(np.zeros(3))


def test_smc_options_validated(prior3):
    with pytest.raises(ValueError):
        SMCSampler(prior3, n_particles=5)
    with pytest.raises(ValueError):
        SMCSampler(prior3, ess_fraction=1.5)
    with pytest.raises(ValueError):
        SMCSampler(prior3, kernel="hmc")
    with pytest.raises(ValueError, match="init_factor"):
        SMCSampler(prior3, init_factor=0)


@pytest.mark.parametrize("kernel", ["independent", "mixture"])
def test_smc_other_kernels(prior3, kernel):
    toy = LinearGaussianToy(prior3, seed=0)
    post = smc(toy, prior3, n_particles=300, seed=7, kernel=kernel)
    z = (post.mean - toy.mean) / toy.sd
    assert np.all(np.abs(z) < 0.5) and np.allclose(post.sd / toy.sd, 1.0, atol=0.3)


def test_all_failed_raises(prior2):
    with pytest.raises(RuntimeError, match="all weights are zero|every"):
        importance_sample(lambda th: np.full(th.shape[0], -np.inf), prior2, n=50, seed=0)
    with pytest.raises(RuntimeError, match="every initial"):
        smc(lambda th: np.full(th.shape[0], -np.inf), prior2, n_particles=20, seed=0)


def test_delayed_acceptance_keeps_the_exact_posterior(prior3):
    """Two-stage moves screened by a cheap, deliberately wrong log-likelihood (flattened and tilted):
    the posterior moments are still the exact ones (the second stage corrects the first), and the
    screen saves full evaluations."""
    from vfcore.inference.importance import batch_function
    from vfcore.inference.problem import Evaluation

    toy = LinearGaussianToy(prior3, n_obs=6, noise=0.05, seed=0)
    full = batch_function(toy)
    tilt = np.array([0.3, 0.002, 0.4]) / np.asarray(prior3.width)

    def cheap(th):
        th = np.atleast_2d(th)
        return 0.6 * Evaluation.coerce(full(th)).loglik + th @ tilt

    R = 8
    means, variances, sims, screened = [], [], [], []
    for s in range(R):
        post = smc(toy, prior3, n_particles=300, seed=200 + s, screen=cheap)
        means.append(post.mean)
        variances.append(post.sd**2)
        sims.append(post.n_simulations)
        screened.append(post.info["n_screened"])
        assert post.info["delayed_acceptance"] and post.info["n_screen_rejected"] > 0
    means, variances = np.asarray(means), np.asarray(variances)
    t = stats.t.ppf(1 - 1e-4, R - 1)
    for arr, exact in ((means, toy.mean), (variances, np.diag(toy.cov))):
        se = arr.std(axis=0, ddof=1) / math.sqrt(R)
        assert np.all(np.abs(arr.mean(axis=0) - exact) < t * se + 2e-3 * np.abs(exact)), (arr.mean(0), exact, se)
    plain = [smc(toy, prior3, n_particles=300, seed=200 + s).n_simulations for s in range(2)]
    assert np.mean(sims) < 0.8 * np.mean(plain), (sims, plain)
    assert np.all(np.asarray(screened) > np.asarray(sims))


def test_delayed_acceptance_is_deterministic_and_validated(prior3):
    toy = LinearGaussianToy(prior3, n_obs=6, noise=0.05, seed=0)
    a = smc(toy, prior3, n_particles=60, seed=5, screen=toy)
    b = smc(toy, prior3, n_particles=60, seed=5, screen=toy)
    assert np.array_equal(a.samples, b.samples) and a.n_simulations == b.n_simulations
    with pytest.raises(ValueError, match="delayed acceptance"):
        SMCSampler(prior3, 60, delayed=True, kernel="independent")
