import numpy as np
import pytest

from vfcore.inference import TABLE2_BOUNDS, Prior
from vfcore.params import PARAM_NAMES, TABLE3


def test_default_is_table2():
    p = Prior.default()
    assert p.names == PARAM_NAMES
    assert p.bounds == TABLE2_BOUNDS
    assert TABLE2_BOUNDS["E_cover"] == (250.0, 950.0) and TABLE2_BOUNDS["x0"] == (7.4, 8.4)


def test_fixed_and_to_params():
    p = Prior.default(fixed={"rho": 1000.0, "x0": 8.0})
    assert "rho" not in p.names and "x0" not in p.names and p.ndim == 5
    theta = (p.lo + p.hi) / 2
    par = p.to_params(theta)
    assert par.rho == 1000.0 and par.x0 == 8.0 and par.E_body == pytest.approx(12.0)
    # neither estimated nor fixed -> Table 3
    q = Prior({"E_body": (9, 15)})
    par = q.to_params(np.array([10.0]))
    assert par.E_cover == TABLE3.E_cover and par.E_body == 10.0
    assert q.full_array(np.array([[10.0], [11.0]])).shape == (2, 7)


def test_sample_logpdf_deterministic():
    p = Prior.default()
    a = p.sample(1000, np.random.default_rng(3))
    b = p.sample(1000, np.random.default_rng(3))
    assert np.array_equal(a, b) and a.shape == (1000, 7)
    assert np.all(p.contains(a))
    lp = p.logpdf(a)
    assert np.allclose(lp, -np.sum(np.log(p.hi - p.lo)))
    out = a[:1].copy()
    out[0, 0] = 100.0
    assert p.logpdf(out)[0] == -np.inf


def test_roundtrip_dict():
    p = Prior.default(fixed={"eta": 3.0})
    q = Prior.from_dict(p.to_dict())
    assert q == p
    import json

    json.dumps(p.to_dict())


@pytest.mark.parametrize(
    "bounds,fixed,match",
    [
        ({"E_bodyy": (9, 15)}, {}, "unknown parameter name"),
        ({"E_body": (15, 9)}, {}, "lo < hi"),
        ({"E_body": (9, 9)}, {}, "lo < hi"),
        ({"E_body": (-1, 9)}, {}, "> 0"),
        ({"p_sub": (-10, 9)}, {}, ">= 0"),
        ({"x0": (7.4, 9.0)}, {}, "x0"),
        ({"E_body": (9, float("nan"))}, {}, "finite"),
        ({"E_body": (9, 15)}, {"E_body": 12}, "both estimated"),
        ({"E_body": (9, 15)}, {"rho": -5}, "> 0"),
        ({"E_body": (9, 15)}, {"bogus": 1}, "unknown parameter name"),
        ({}, {"E_body": 12}, "at least one"),
        ({"E_body": (9,)}, {}, "pair"),
    ],
)
def test_prior_validation(bounds, fixed, match):
    with pytest.raises(ValueError, match=match):
        Prior(bounds, fixed)


def test_default_unknown_fixed():
    with pytest.raises(ValueError, match="unknown parameter name"):
        Prior.default(fixed={"Ebody": 1.0})
