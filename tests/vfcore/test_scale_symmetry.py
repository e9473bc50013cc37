"""The common-scale symmetry of the model: multiplying E_body, E_cover, E_lig, p_sub, rho and eta by one
factor c (x0 unchanged) leaves the glottal area waveform unchanged, scales every contact quantity by c
and the flow rate by sqrt(c) (:ref:`inference-scale-the-common-scale-what-a`). Each fold-side term of the model
carries one power of mass (stiffness, subglottal and Bernoulli loads, mass, damping) and the air density
enters the flow velocity only, so c is a change of the unit of mass that lengths and times do not see.
A GAW likelihood therefore cannot tell theta from c * theta; a measured parameter can."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest

from vfcore import TABLE3, SimConfig, simulate
from vfcore.inference import Prior, Problem, evaluate
from vfcore.inference.identify import SCALED

CFG = SimConfig(mesh="coarse", dt=1e-4, duration=0.3, discard=0.1, fps=2000.0)


def scaled(p, c, names=SCALED):
    return p.replace(**{n: getattr(p, n) * c for n in names})


@cache
def _sim(c: float, contact: str = "projection"):
    r = simulate(scaled(TABLE3, c), CFG.replace(contact=contact))
    assert r.ok, r.message
    return r


def _rel(a, b):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape and b.size
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.mark.parametrize("contact", ["projection", "layer"])
@pytest.mark.parametrize("c", [0.25, 4.0])
def test_a_power_of_four_scale_is_bit_exact(c, contact):
    """With c = 4^k every rounding in the model commutes with the scaling (multiplying by a power of
    two is exact in binary floating point, and so is sqrt(c) = 2^k where the flow takes a square
    root), so the symmetry holds bit for bit: a failure here is a term that does not scale, never
    round-off. The contact layer's spring and dashpot are the cover's modulus and viscosity over a
    length, so they scale with c too."""
    r0, r = _sim(1.0, contact), _sim(c, contact)
    assert np.array_equal(r.gaw, r0.gaw) and np.array_equal(r.gaw_hr, r0.gaw_hr)
    assert r.f0 == r0.f0
    assert np.array_equal(r.contact_pressure, c * r0.contact_pressure)
    assert np.array_equal(r.flow, math.sqrt(c) * r0.flow)
    assert r0.cycles.max_contact_pressure.min() > 0 and r0.cycles.mean_flow.min() > 0


@pytest.mark.parametrize("c", [0.8, 1.25])
def test_scaled_parameters_give_the_same_gaw_and_scaled_products(c):
    """Any other c: equal up to round-off grown over the simulation (measured ~5e-9 mm^2 on this
    window; the bound leaves two decades for other compilers and libraries)."""
    r0, r = _sim(1.0), _sim(c)
    # the waveform and everything geometric or temporal: unchanged
    assert np.max(np.abs(r.gaw - r0.gaw)) < 1e-6
    assert np.max(np.abs(r.gaw_hr - r0.gaw_hr)) < 1e-6
    assert np.max(np.abs(r.width - r0.width)) < 1e-6
    assert math.isfinite(r0.f0) and abs(r.f0 - r0.f0) < 1e-6
    assert r.cycles.period.size == r0.cycles.period.size >= 5
    # it vibrates with contact and flow, so the scalings below are not about zeros
    assert r0.cycles.max_contact_pressure.min() > 0 and r0.cycles.mean_flow.min() > 0
    # every contact quantity the result exposes: times c
    assert _rel(r.contact_pressure, c * r0.contact_pressure) < 1e-6
    assert _rel(r.contact_force, c * r0.contact_force) < 1e-6
    for name in ("mean_contact_pressure", "max_contact_pressure"):
        a, b = getattr(r.cycles, name), c * getattr(r0.cycles, name)
        assert np.max(np.abs(a - b) / np.abs(b)) < 1e-6, name
    # the flow: times sqrt(c)
    assert _rel(r.flow, math.sqrt(c) * r0.flow) < 1e-6
    np.testing.assert_allclose(r.cycles.mean_flow, math.sqrt(c) * r0.cycles.mean_flow, rtol=1e-6, atol=0)


@cache
def _observation():
    """The Table 3 waveform's first 300 frames plus N(0, 1 mm^2) noise."""
    y = _sim(1.0).gaw[:300]
    return y + np.random.default_rng(5).normal(0.0, 1.0, y.size)


def _problem(**kw):
    return Problem(_observation(), 2000.0, Prior.default(fixed={"x0": 8.4}), sigma_e=1.0, config=CFG, **kw)


@pytest.mark.parametrize("noise", ["fixed", "marginal"])
def test_the_likelihood_cannot_see_the_common_scale(noise):
    """evaluate (the lock-step batch kernel, Problem.loglik) gives theta, 0.9 theta and 1.1 theta the same
    log-likelihood to 1e-6 nats (|log L| is ~ 400; the likelihood is defined outside the prior box, where
    0.9 rho lies); moving five of the six (rho kept) is seen at once."""
    pb = _problem(noise=noise)
    theta = TABLE3.as_array()[:6]
    rows = np.array([theta, 0.9 * theta, 1.1 * theta, np.r_[1.1 * theta[:4], theta[4], 1.1 * theta[5]]])
    ev = evaluate(rows, pb)
    assert ev.ok.all(), ev.messages
    ll = ev.loglik
    assert abs(ll[1] - ll[0]) < 1e-6 and abs(ll[2] - ll[0]) < 1e-6, ll
    assert ll[0] - ll[3] > 1.0, ll
    # the contact pressure the likelihood cannot see scales with c
    np.testing.assert_allclose(ev.max_contact[1:3], [0.9 * ev.max_contact[0], 1.1 * ev.max_contact[0]], rtol=1e-8)
    np.testing.assert_allclose(ev.mean_flow[1:3], np.sqrt([0.9, 1.1]) * ev.mean_flow[0], rtol=1e-8)


def test_a_measured_p_sub_breaks_the_symmetry_by_its_gaussian_term():
    """With p_sub measured as 1000 +- 40 Pa the scaled draws differ by exactly the difference of the
    Gaussian log densities at their p_sub values."""
    m, s = 1000.0, 40.0
    pb = _problem(measurements={"p_sub": (m, s)})
    theta = TABLE3.as_array()[:6]
    ev = evaluate(np.array([theta, 0.9 * theta, 1.1 * theta]), pb)
    p = TABLE3.p_sub * np.array([1.0, 0.9, 1.1])
    gauss = -0.5 * ((p - m) / s) ** 2 - math.log(s * math.sqrt(2 * math.pi))
    gaw_only = evaluate(np.array([theta, 0.9 * theta, 1.1 * theta]), _problem()).loglik
    np.testing.assert_allclose(ev.loglik - gaw_only, gauss, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ev.loglik[1:] - ev.loglik[0], gauss[1:] - gauss[0], rtol=0, atol=1e-5)
