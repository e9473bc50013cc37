import math
import warnings

import numpy as np
import pytest
from scipy.special import logsumexp

from vfcore.inference import (
    DegenerateEnsembleWarning,
    ess,
    log_evidence_is,
    normalize_log_weights,
    pareto_k,
    systematic_resample,
    weighted_quantiles,
)
from vfcore.inference.diagnostics import degeneracy_warnings


def test_ess_known_weights():
    assert ess(np.zeros(50)) == pytest.approx(50.0)
    assert ess(np.array([0.0, 0.0, -np.inf, -np.inf])) == pytest.approx(2.0)
    assert ess(np.array([0.0, -np.inf, -np.inf])) == pytest.approx(1.0)
    w = np.array([0.5, 0.25, 0.25])
    assert ess(np.log(w) + 123.0) == pytest.approx(1.0 / np.sum(w**2))
    with pytest.raises(RuntimeError, match="all weights are zero"):
        ess(np.full(3, -np.inf))


def test_normalize_huge_logliks():
    lw = normalize_log_weights(np.array([-1e6, -1e6 + math.log(3.0)]))
    assert np.allclose(np.exp(lw), [0.25, 0.75])


def test_log_evidence_known():
    z, se = log_evidence_is(np.full(10, -3.0))
    assert z == pytest.approx(-3.0) and se == pytest.approx(0.0, abs=1e-12)
    ll = np.array([0.0, math.log(3.0), -np.inf, math.log(4.0)])
    z, se = log_evidence_is(ll)
    L = np.exp(ll)
    assert z == pytest.approx(math.log(L.mean()))
    assert se == pytest.approx(L.std(ddof=1) / math.sqrt(L.size) / L.mean())  # delta method
    assert log_evidence_is(np.full(3, -np.inf))[0] == -math.inf


def test_log_evidence_se_is_calibrated():
    """The delta-method s.e. matches the spread of the estimator over replications."""
    rng = np.random.default_rng(0)
    ests, ses = [], []
    for _ in range(400):
        ll = -0.5 * (rng.uniform(-1, 1, 2000) / 0.2) ** 2  # Z = 0.2 sqrt(2 pi)/2 * erf-ish
        z, se = log_evidence_is(ll)
        ests.append(z)
        ses.append(se)
    assert np.std(ests) == pytest.approx(np.mean(ses), rel=0.15)


def test_systematic_resample_counts():
    rng = np.random.default_rng(1)
    for _ in range(50):
        w = rng.random(17) ** 3
        m = int(rng.integers(5, 100))
        idx = systematic_resample(w, m, rng)
        counts = np.bincount(idx, minlength=w.size)
        expect = m * w / w.sum()
        assert counts.sum() == m
        assert np.all(counts >= np.floor(expect) - 1e-9) and np.all(counts <= np.ceil(expect) + 1e-9)
        assert np.all(np.diff(idx) >= 0)
    # equal weights: every index exactly once
    assert np.array_equal(systematic_resample(np.ones(10), 10, rng), np.arange(10))
    # zero weights are never chosen
    idx = systematic_resample(np.array([0.0, 1.0, 0.0, 2.0]), 1000, rng)
    assert set(np.unique(idx)) == {1, 3}


def test_systematic_resample_unbiased():
    w = np.array([0.1, 0.05, 0.6, 0.25])
    rng = np.random.default_rng(2)
    tot = np.zeros(4)
    for _ in range(4000):
        tot += np.bincount(systematic_resample(w, 7, rng), minlength=4)
    assert np.allclose(tot / 4000, 7 * w, atol=0.05)


def test_systematic_resample_rejects_bad():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError):
        systematic_resample(np.array([1.0, -1.0]), 3, rng)
    with pytest.raises(ValueError):
        systematic_resample(np.zeros(3), 3, rng)


def test_pareto_k_known_tail():
    rng = np.random.default_rng(4)
    # weights with a Pareto tail of shape k: w = U^(-k)
    for k_true in (0.3, 0.9):
        lw = -k_true * np.log(rng.random(20000))
        assert pareto_k(lw) == pytest.approx(k_true, abs=0.15)
    assert pareto_k(np.zeros(100)) == 0.0
    assert math.isnan(pareto_k(np.zeros(3)))


def test_weighted_quantiles():
    x = np.arange(1.0, 1001.0)
    q = weighted_quantiles(x, np.ones_like(x), [0.05, 0.5, 0.95])
    assert np.allclose(q, np.quantile(x, [0.05, 0.5, 0.95], method="hazen"))
    # integer weights ~ repetition (identical up to the plotting-position convention)
    rng = np.random.default_rng(0)
    xs = rng.normal(size=2000)
    k = rng.integers(0, 4, size=2000)
    q1 = weighted_quantiles(xs, k.astype(float), [0.1, 0.5, 0.9])
    assert np.allclose(q1, np.quantile(np.repeat(xs, k), [0.1, 0.5, 0.9]), atol=0.01)


def test_degeneracy_warning_is_loud():
    with pytest.warns(DegenerateEnsembleWarning, match="DEGENERATE"):
        msgs = degeneracy_warnings(5.0, 1000, 0.2)
    assert len(msgs) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert degeneracy_warnings(500.0, 1000, 0.2) == []
    with pytest.warns(DegenerateEnsembleWarning, match="Pareto k"):
        degeneracy_warnings(500.0, 1000, 0.9)


def test_logsumexp_consistency():
    lw = normalize_log_weights(np.array([0.0, 1.0, 2.0]))
    assert logsumexp(lw) == pytest.approx(0.0, abs=1e-12)
