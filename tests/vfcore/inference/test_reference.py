"""SMC started from a reference distribution (generalized stepping-stone path) against exact answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from linear_gaussian import LinearGaussianToy
from scipy import stats

from vfcore.inference import Prior, smc
from vfcore.inference.reference import GaussianReference, reference_from_posterior


@pytest.fixture(scope="module")
def prior3():
    return Prior.default(fixed={"rho": 1051.0, "eta": 3.0, "x0": 8.4, "p_sub": 900.0})


def test_reference_density_is_normalised_and_matches_its_samples(prior3):
    rng = np.random.default_rng(0)
    mu = prior3.lo + 0.9 * prior3.width  # near a corner: much of the Gaussian is truncated
    ref = GaussianReference(prior3, mu, np.diag((0.2 * prior3.width) ** 2), eps=0.1)
    assert 0.05 < ref.p_inside[0] < 0.5
    u = prior3.sample(400_000, rng)  # E_p[q / p] = 1: q integrates to one on the box
    r = np.exp(ref.logpdf(u) - prior3.logpdf(u))
    assert abs(r.mean() - 1.0) < 4 * r.std() / math.sqrt(r.size)
    x = ref.sample(200_000, rng)  # E_q[p / q] = 1: the samples follow the density
    assert np.all(prior3.contains(x))
    s = np.exp(prior3.logpdf(x) - ref.logpdf(x))
    assert abs(s.mean() - 1.0) < 4 * s.std() / math.sqrt(s.size)
    assert np.all(ref.logpdf(prior3.hi[None, :] + 1.0) == -np.inf)


def test_reference_rejects_bad_input(prior3):
    with pytest.raises(ValueError, match="positive definite"):
        GaussianReference(prior3, prior3.lo + 0.5 * prior3.width, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="dimensions"):
        GaussianReference(prior3, np.zeros(5), np.eye(5))
    with pytest.raises(ValueError, match="no mass"):
        GaussianReference(prior3, prior3.hi + 100 * prior3.width, np.diag((1e-3 * prior3.width) ** 2))


@pytest.mark.parametrize("offset_sd", [0.0, 3.0])
def test_smc_from_reference_exact(prior3, offset_sd):
    """Log-evidence and posterior mean of the reference-started SMC against the exact answers,
    with the reference centred on the posterior and 3 posterior sds away from it; and fewer
    simulations than the prior-started sampler when the reference is right."""
    toy = LinearGaussianToy(prior3, n_obs=6, noise=0.05, seed=0)
    sd = np.sqrt(np.diag(toy.cov))
    ref = GaussianReference(prior3, toy.mean + offset_sd * sd, 4.0 * toy.cov, eps=0.1, seed=1)
    R = 8
    logz, means, sims, sims_prior = [], [], [], []
    for s in range(R):
        post = smc(toy, prior3, n_particles=200, seed=300 + s, reference=ref)
        assert post.info["reference"] is True
        logz.append(post.log_evidence)
        means.append(post.mean)
        sims.append(post.n_simulations)
        if offset_sd == 0.0:
            sims_prior.append(smc(toy, prior3, n_particles=200, seed=300 + s).n_simulations)
    logz, means = np.asarray(logz), np.asarray(means)
    t = stats.t.ppf(1 - 1e-4, R - 1)
    v = logz.var(ddof=1)
    assert abs(logz.mean() + v / 2 - toy.log_evidence) < t * math.sqrt(v / R) + 0.02, (logz, toy.log_evidence)
    se = means.std(axis=0, ddof=1) / math.sqrt(R)
    assert np.all(np.abs(means.mean(axis=0) - toy.mean) < t * se + 0.05 * sd)
    if offset_sd == 0.0:
        assert np.mean(sims) < 0.7 * np.mean(sims_prior), (np.mean(sims), np.mean(sims_prior))


def test_reference_from_posterior_covers_the_fit(prior3):
    toy = LinearGaussianToy(prior3, n_obs=6, noise=0.05, seed=0)
    post = smc(toy, prior3, n_particles=100, seed=5)
    ref = reference_from_posterior(prior3, post, inflate=2.0, wide=0.1)
    assert np.allclose(ref.mean, post.mean, rtol=1e-9, atol=0.0)
    assert ref.cov.shape == (2, 3, 3)
    assert np.all(np.sqrt(np.diag(ref.cov[0])) >= 2.0 * post.sd * (1 - 1e-9))
    assert np.all(np.sqrt(np.diag(ref.cov[1])) >= 0.1 * prior3.width * (1 - 1e-9))
    # the two-component reference is a normalised density too
    u = prior3.sample(200_000, np.random.default_rng(3))
    r = np.exp(ref.logpdf(u) - prior3.logpdf(u))
    assert abs(r.mean() - 1.0) < 4 * r.std() / math.sqrt(r.size)
    wrong = Prior({"p_sub": (400.0, 1800.0), "rho": (1000.0, 1100.0), "eta": (1.0, 5.0)})
    with pytest.raises(ValueError, match="not the first ones"):
        reference_from_posterior(wrong, post)
