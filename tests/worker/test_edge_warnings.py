"""Posteriors at the edges get plain warnings: a parameter piled against a bound of the prior's box
(vfcore.inference.identify.at_bounds) and a fit far above the recording's own noise (worker.reduce)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import toy_model  # noqa: F401  (registers model "toy")

from vfcore.inference import Posterior, Prior
from vfcore.inference.identify import BOUND_FRACTION, BOUND_MASS_WARN, at_bounds
from worker.jobspec import JobSpec
from worker.reduce import MISFIT_RATIO_WARN, edge_warnings, noise_check

PRIOR = Prior(
    {"E_body": (9.0, 15.0), "p_sub": (400.0, 1800.0)},
    {"E_cover": 636.2, "E_lig": 1.808, "rho": 1051.0, "eta": 3.079, "x0": 8.4},
)


def posterior(cols: dict, prior: Prior = PRIOR, seed: int = 0) -> Posterior:
    X = np.stack([np.clip(cols[n], *prior.bounds[n]) for n in prior.names], axis=1)
    lw = np.full(X.shape[0], -np.log(X.shape[0]))
    return Posterior.from_weighted(prior.names, X, lw, rng=np.random.default_rng(seed), check=False)


def test_piled_on_two_bounds_names_both():
    """The case of the issue: E_body 14.976 +- 0.024 (upper bound 15), p_sub 401.1 +- 0.9 (lower bound 400)."""
    rng = np.random.default_rng(1)
    post = posterior({"E_body": rng.normal(14.976, 0.024, 2000), "p_sub": rng.normal(401.1, 0.9, 2000)})
    rows = {r["name"]: r for r in at_bounds(post, PRIOR)}
    assert set(rows) == {"E_body", "p_sub"}
    assert rows["E_body"]["bound"] == "upper" and rows["E_body"]["value"] == 15.0 and rows["E_body"]["mass"] > 0.99
    assert rows["p_sub"]["bound"] == "lower" and rows["p_sub"]["value"] == 400.0 and rows["p_sub"]["mass"] > 0.99
    w = rows["E_body"]["warning"]
    assert w.startswith("AT PRIOR BOUND: E_body = 14.97") and "upper bound 15 kPa" in w and "[9, 15]" in w


@pytest.mark.parametrize(
    "cols",
    [
        {"E_body": ("normal", 12.0, 0.5), "p_sub": ("normal", 1000.0, 50.0)},  # well inside
        {"E_body": ("uniform", 9.0, 15.0), "p_sub": ("uniform", 400.0, 1800.0)},  # the prior itself: 2 % per edge
    ],
)
def test_no_warning_inside_or_flat(cols):
    rng = np.random.default_rng(2)
    post = posterior({n: getattr(rng, kind)(a, b, 4000) for n, (kind, a, b) in cols.items()})
    assert at_bounds(post, PRIOR) == []


@pytest.mark.parametrize("frac,flagged", [(0.30, True), (0.10, False)])
def test_the_threshold(frac, flagged):
    """``frac`` of the draws in the upper edge strip, the rest mid-box: flagged above BOUND_MASS_WARN only."""
    n = 2000
    k = int(frac * n)
    rng = np.random.default_rng(3)
    e = np.concatenate([rng.uniform(15.0 - 0.9 * BOUND_FRACTION * 6.0, 15.0, k), rng.normal(12.0, 0.3, n - k)])
    post = posterior({"E_body": e, "p_sub": rng.normal(1000.0, 50.0, n)})
    rows = at_bounds(post, PRIOR)
    assert (frac > BOUND_MASS_WARN) == flagged
    assert [r["name"] for r in rows] == (["E_body"] if flagged else [])


def _spec() -> JobSpec:
    t = np.arange(800) / 4000.0
    areas = (10.0 * (1 - np.cos(2 * np.pi * 70.0 * t))).tolist()
    return JobSpec.model_validate(
        {
            "model": "toy",
            "gaw": {"areas": areas, "fps": 4000.0},
            "priors": {"E_body": [9.0, 15.0], "p_sub": [400.0, 1800.0]},
            "fixed": {"E_cover": 636.2, "E_lig": 1.808, "rho": 1051.0, "eta": 3.079, "x0": 8.4},
            "sampler": {"kind": "is", "n_samples": 10},
            "duration": 0.35,
            "discard": 0.2,
            "sigma_e": 1.0,
            "seed": 0,
        }
    )


def _obs_and_pred(misfit: bool, n_draws: int = 50):
    rng = np.random.default_rng(4)
    t = np.arange(600) / 4000.0
    clean = 10.0 * (1 - np.cos(2 * np.pi * 108.0 * t))
    obs = clean + rng.normal(0.0, 0.3, t.size)
    fit = 10.0 * (1 - np.cos(2 * np.pi * 60.0 * t)) if misfit else clean
    return obs, SimpleNamespace(gaw=np.tile(fit, (n_draws, 1)) + rng.normal(0, 0.01, (n_draws, t.size)))


@pytest.mark.parametrize("misfit", [True, False])
def test_misfit_against_the_recordings_noise(misfit):
    """A 60-Hz fit through a 108-Hz recording with noise sd 0.3 mm^2 gets a MISFIT warning with the numbers;
    the right waveform (residual = the noise) does not."""
    spec = _spec()
    obs, pred = _obs_and_pred(misfit)
    rng = np.random.default_rng(5)
    post = posterior(
        {"E_body": rng.normal(12.0, 0.5, 500), "p_sub": rng.normal(1000.0, 50.0, 500)}, prior=spec.to_prior()
    )
    post.obs_gaw = obs
    nc = noise_check(spec, post, pred)
    assert nc["recording_noise_sd"] == pytest.approx(0.3, rel=0.25)
    ws = edge_warnings(spec, post, nc)
    if misfit:
        assert nc["misfit_ratio"] > MISFIT_RATIO_WARN
        assert len(ws) == 1 and ws[0].startswith("MISFIT: the fit's residual RMS is")
        assert f"{nc['residual_rms']['q50']:.3g} mm^2" in ws[0]
    else:
        assert nc["misfit_ratio"] < 1.5 and ws == []


def test_edge_warnings_include_the_bounds():
    spec = _spec()
    rng = np.random.default_rng(6)
    post = posterior(
        {"E_body": rng.normal(14.99, 0.01, 500), "p_sub": rng.normal(1000.0, 50.0, 500)}, prior=spec.to_prior()
    )
    ws = edge_warnings(spec, post, None)
    assert len(ws) == 1 and ws[0].startswith("AT PRIOR BOUND: E_body")
