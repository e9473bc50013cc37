"""The identifiability table (vfcore.inference.identify) on synthetic posteriors with a known ridge.

The exact symmetry of the model (tests/vfcore/test_scale_symmetry.py) means that where the data fix the
five scale-invariant combinations, the posterior along the common-scale ray is the prior's conditional
density there: uniform in the parameters, i.e. ``prop. to prod theta_i = c^k`` in log coordinates, on the
stretch of the ray inside the box. The draws below are built that way (plus a small jitter across the
ridge), so what the table must say about them is known in advance."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import integrate

from vfcore.inference import Posterior, Prior
from vfcore.inference.identify import SCALED, _ray_sd, identify, uniform_log_moments
from vfcore.params import TABLE3

BRIEF = "absolute moduli, p_sub, contact pressure and flow are set by the prior's box along the common scale"


def ridge_posterior(
    prior: Prior,
    log_c: np.ndarray,
    weights: np.ndarray,
    seed: int = 0,
    jitter: float = 0.002,
    x0: tuple[float, float] = (8.0, 0.005),
) -> Posterior:
    """Draws at Table 3 multiplied by ``c = exp(log_c)`` in the free scaled parameters, each jittered by
    ``jitter`` in log; a free x0 is drawn independently from N(x0)."""
    rng = np.random.default_rng(seed)
    n = log_c.size
    cols = []
    for name in prior.names:
        if name == "x0":
            cols.append(rng.normal(x0[0], x0[1], n))
        else:
            cols.append(getattr(TABLE3, name) * np.exp(log_c + jitter * rng.standard_normal(n)))
    X = np.stack(cols, axis=1)
    inside = prior.contains(X)
    w = np.where(inside, weights, 0.0)
    with np.errstate(divide="ignore"):
        lw = np.log(w)
    return Posterior.from_weighted(prior.names, X, lw, rng=np.random.default_rng(seed + 1), check=False)


def ray_range(prior: Prior) -> tuple[float, float]:
    """log c range of the ray through Table 3 inside the box (the free scaled parameters)."""
    free = [n for n in SCALED if n in prior.names]
    lo = max(math.log(prior.bounds[n][0] / getattr(TABLE3, n)) for n in free)
    hi = min(math.log(prior.bounds[n][1] / getattr(TABLE3, n)) for n in free)
    return lo, hi


def on_the_ray(prior: Prior, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """log c uniform on the ray, weighted by c^k (the prior's conditional density along it)."""
    k = sum(n_ in prior.names for n_ in SCALED)
    lo, hi = ray_range(prior)
    lc = np.random.default_rng(seed + 99).uniform(lo, hi, n)
    return lc, np.exp(k * lc)


def _quad_sd(density, a, b):
    z = integrate.quad(density, a, b)[0]
    m = integrate.quad(lambda s: s * density(s), a, b)[0] / z
    v = integrate.quad(lambda s: (s - m) ** 2 * density(s), a, b)[0] / z
    return math.sqrt(v)


@pytest.mark.parametrize("lo, hi", [(950.0, 1200.0), (0.0, 1800.0), (1.0, 7.0), (9.0, 15.0), (999.9, 1000.1)])
def test_log_moments_of_a_uniform_prior_equal_quadrature(lo, hi):
    mean, var = uniform_log_moments(lo, hi)
    m = integrate.quad(lambda x: math.log(x), lo, hi)[0] / (hi - lo)
    v = integrate.quad(lambda x: (math.log(x) - m) ** 2, lo, hi)[0] / (hi - lo)
    assert mean == pytest.approx(m, rel=1e-9, abs=1e-12)
    assert var == pytest.approx(v, rel=1e-6)


@pytest.mark.parametrize("length, rate", [(0.573, math.sqrt(6)), (1.2, math.sqrt(5)), (1e-5, 2.0), (4.0, 3.0)])
def test_the_ray_sd_is_that_of_the_truncated_exponential(length, rate):
    assert _ray_sd(length, rate) == pytest.approx(_quad_sd(lambda s: math.exp(rate * s), 0.0, length), rel=1e-6)


def test_exact_ridge_is_the_least_narrowed_direction_and_warns():
    prior = Prior.default()  # all seven free; x0 independent of the ridge
    post = ridge_posterior(prior, *on_the_ray(prior, 40_000))
    d = identify(post, prior).to_dict()
    json.dumps(d)  # JSON-able as stored with a job
    # (b) the least narrowed principal direction is the common scale, with no weight on x0
    first = d["principal"][0]
    assert first["scale_alignment"] > 0.999
    assert abs(first["loadings"]["x0"]) < 0.01
    assert all(r["ratio"] < first["ratio"] / 10 for r in d["principal"][1:] if r["scale_alignment"] < 0.5)
    # (c) along the scale: the posterior is as wide as the box lets the ray be (Table 2 at Table 3: the rho box)
    s = d["scale"]
    lo, hi = ray_range(prior)
    assert (lo, hi) == (pytest.approx(math.log(950 / 1051)), pytest.approx(math.log(1200 / 1051)))
    k = math.sqrt(6)
    assert s["ray_prior_sd"] == pytest.approx(_quad_sd(lambda t: math.exp(k * t), 0.0, k * (hi - lo)), rel=1e-3)
    assert s["ray_ratio"] == pytest.approx(1.0, abs=0.05)
    assert s["exact_symmetry"] and s["set_by_prior"] and s["names"] == list(SCALED)
    # the narrow rho box hides the ridge from the unconditional comparison: half the prior sd is not reached
    assert s["ratio"] < 0.5 < s["ray_ratio"]
    # (a) rho's marginal is its whole box; the others look narrowed, but only because rho's box cuts the ray
    rows = {r["name"]: r for r in d["parameters"]}
    assert rows["rho"]["ratio"] > 0.85 and rows["p_sub"]["ratio"] < 0.3
    # (c) the combinations are fixed (jitter only) at their Table 3 values, whatever the scale
    combo = {c["label"]: c for c in d["combinations"]}
    assert combo["E_cover/p_sub"]["value"] == pytest.approx(636.2 / 989.9, rel=2e-3)
    assert combo["E_body/p_sub"]["value"] == pytest.approx(12.15e3 / 989.9, rel=2e-3)
    assert combo["eta^2/(rho*p_sub)"]["value"] == pytest.approx(0.3079**2 / (1051.0 * 989.9), rel=2e-3)
    assert combo["eta^2/(rho*p_sub)"]["unit"] == "m^2" and combo["rho/p_sub"]["unit"] == "s^2/m^2"
    assert combo["eta/p_sub"]["unit"] == "s" and combo["E_lig/p_sub"]["unit"] == "1"
    assert all(c["ratio"] < 0.02 for c in d["combinations"])
    # (d) the plain warning
    assert len(d["warnings"]) == 1 and d["warnings"][0].startswith("COMMON SCALE") and BRIEF in d["warnings"][0]
    assert "--measure p_sub=" in d["warnings"][0]


def test_a_tight_p_sub_measurement_anchors_the_scale():
    """The same ridge with p_sub measured at 989.9 +- 1 % : the common factor's sd in log is the
    measurement's relative sd, and nothing warns."""
    prior = Prior.default(fixed={"x0": 8.4})
    lc, w = on_the_ray(prior, 40_000, seed=3)
    m, sd = 989.9, 9.899
    w = w * np.exp(-0.5 * ((TABLE3.p_sub * np.exp(lc) - m) / sd) ** 2)
    post = ridge_posterior(prior, lc, w, seed=3)
    d = identify(post, prior, measurements={"p_sub": (m, sd)}).to_dict()
    s = d["scale"]
    assert s["log_c_sd"] == pytest.approx(0.01, rel=0.15)
    assert not s["exact_symmetry"] and not s["set_by_prior"] and s["measured"] == ["p_sub"]
    assert s["ray_ratio"] < 0.25
    assert d["warnings"] == []
    assert any(a.startswith("measured p_sub = 989.9") for a in d["anchors"])


def test_a_loose_measurement_does_not_silence_the_warning():
    """p_sub measured to +- 50 %: the rho box still sets the scale, and the warning says so."""
    prior = Prior.default(fixed={"x0": 8.4})
    lc, w = on_the_ray(prior, 20_000, seed=4)
    m, sd = 989.9, 495.0
    w = w * np.exp(-0.5 * ((TABLE3.p_sub * np.exp(lc) - m) / sd) ** 2)
    d = identify(ridge_posterior(prior, lc, w, seed=4), prior, measurements={"p_sub": (m, sd)}).to_dict()
    assert d["scale"]["set_by_prior"] and not d["scale"]["exact_symmetry"]
    assert d["scale"]["ray_ratio"] > 0.9
    w = d["warnings"]
    assert len(w) == 1 and "measured p_sub" in w[0] and "rest partly on the prior's box" in w[0], w


def test_a_fixed_density_that_anchors_nothing_is_seen_from_the_data():
    """rho fixed, the other five on a ridge (the GAW would then determine the scale; here the draws
    pretend it did not): the check from the draws fires, naming the fixed anchor."""
    prior = Prior.default(fixed={"x0": 8.4, "rho": 1051.0})
    d = identify(ridge_posterior(prior, *on_the_ray(prior, 20_000, seed=5), seed=5), prior).to_dict()
    s = d["scale"]
    assert s["names"] == ["E_body", "E_cover", "E_lig", "p_sub", "eta"]
    assert not s["exact_symmetry"] and s["set_by_prior"] and s["ray_ratio"] == pytest.approx(1.0, abs=0.05)
    assert any("fixed rho = 1051" in w for w in d["warnings"])
    assert d["anchors"] == ["fixed rho = 1051 kg/m^3"]


def test_a_determined_scale_with_a_fixed_density_does_not_warn():
    prior = Prior.default(fixed={"x0": 8.4, "rho": 1051.0})
    lc = np.random.default_rng(6).normal(0.0, 0.01, 20_000)
    d = identify(ridge_posterior(prior, lc, np.ones(lc.size), seed=6), prior).to_dict()
    assert d["scale"]["ray_ratio"] < 0.1 and not d["scale"]["set_by_prior"] and d["warnings"] == []
    assert d["scale"]["log_c_sd"] == pytest.approx(0.01, rel=0.1)


def test_a_posterior_piled_against_the_box_along_the_scale_warns():
    """Narrow along the scale but pressed against the E_body box (the data want a larger scale than the
    box allows): the draws' own positions along their rays show it."""
    prior = Prior.default(fixed={"x0": 8.4, "rho": 1051.0})
    top = math.log(15.0 / 12.15) - 0.004  # E_body's upper bound limits the ray
    lc = top - np.abs(np.random.default_rng(7).normal(0.0, 0.005, 20_000))
    d = identify(ridge_posterior(prior, lc, np.ones(lc.size), seed=7, jitter=0.0005), prior).to_dict()
    s = d["scale"]
    assert s["ray_ratio"] < 0.1  # narrow: not the width that warns
    assert s["edge_mass"][1] > 0.5 and s["set_by_prior"]
    assert any("outer 5%" in w for w in d["warnings"])


def test_without_two_free_scaled_parameters_there_is_no_scale_to_report():
    fixed = {n: getattr(TABLE3, n) for n in ("E_body", "E_cover", "E_lig", "rho", "eta")}
    prior = Prior.default(fixed=fixed)
    rng = np.random.default_rng(8)
    X = np.stack([rng.normal(1000.0, 20.0, 500), rng.normal(8.0, 0.005, 500)], axis=1)
    post = Posterior.from_weighted(prior.names, X, np.zeros(500), rng=rng, check=False)
    r = identify(post, prior)
    assert r.scale is None and r.combinations == [] and r.warnings == []
    assert [p["name"] for p in r.parameters] == ["p_sub", "x0"]
    assert r.parameters[0]["ratio"] == pytest.approx(post.sd[0] / (1400.0 / math.sqrt(12)))
    assert "p_sub" in r.format()


def test_resampled_draws_give_the_weighted_answer_and_names_must_match():
    prior = Prior.default(fixed={"x0": 8.4})
    post = ridge_posterior(prior, *on_the_ray(prior, 20_000, seed=9), seed=9)
    a, b = identify(post, prior), identify(post, prior, use="resampled")
    assert b.scale["ray_ratio"] == pytest.approx(a.scale["ray_ratio"], rel=0.05)
    assert b.principal[0]["scale_alignment"] > 0.999
    with pytest.raises(ValueError, match="differ from the prior"):
        identify(post, Prior.default())
    with pytest.raises(ValueError, match="use must be"):
        identify(post, prior, use="both")
