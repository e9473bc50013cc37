import numpy as np
import pytest
from inf_helpers import synthetic_gaw

from vfcore.config import SimConfig
from vfcore.inference import Prior, Problem, importance_sample, validate_observation


class Counting:
    def __init__(self):
        self.calls = 0

    def __call__(self, params, config):  # pragma: no cover - must never run
        self.calls += 1
        raise AssertionError("simulation ran")


def test_valid_observation_passes(obs_gaw):
    y = validate_observation(obs_gaw, 2000.0)
    assert y.dtype == float and y.shape == obs_gaw.shape


@pytest.mark.parametrize(
    "mutate,match",
    [
        (lambda y: np.where(np.arange(y.size) == 17, np.nan, y), "NaN"),
        (lambda y: np.where(np.arange(y.size) == 3, np.inf, y), "NaN/inf"),
        (lambda y: np.full(600, 3.0), "constant"),
        (lambda y: y[:25], "cycles"),  # 25 frames at 2000 fps = 1.5 cycles of 120 Hz
        (lambda y: y.reshape(20, 30), "1D"),
        (lambda y: y[:2], "two cycles"),
    ],
)
def test_bad_observation(obs_gaw, mutate, match):
    with pytest.raises(ValueError, match=match):
        validate_observation(mutate(obs_gaw), 2000.0)


def test_bad_fps(obs_gaw):
    with pytest.raises(ValueError, match="fps"):
        validate_observation(obs_gaw, 0.0)


def test_problem_rejects_before_simulation(obs_gaw):
    prior = Prior.default()
    bad = obs_gaw.copy()
    bad[5] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        Problem(bad, 2000.0, prior)
    with pytest.raises(ValueError, match="sigma_e"):
        Problem(obs_gaw, 2000.0, prior, sigma_e=0.0)
    with pytest.raises(ValueError, match="model"):
        Problem(obs_gaw, 2000.0, prior, model="lumped")
    # a simulation too short to align two cycles
    with pytest.raises(ValueError, match="too short"):
        Problem(obs_gaw, 2000.0, prior, config=SimConfig(duration=0.26, discard=0.25))


def test_problem_roundtrip_and_window(obs_gaw):
    p = Problem(
        obs_gaw,
        2000.0,
        Prior.default(fixed={"x0": 8.4}),
        sigma_e=1.5,
        config=SimConfig(mesh="coarse", fps=4000.0, dt=1e-4),
    )
    assert p.config.fps == 2000.0  # camera rate wins
    max_lag, n_cmp = p.window
    assert n_cmp <= obs_gaw.size and max_lag > 0
    q = Problem.from_dict(p.to_dict())
    assert np.array_equal(q.obs_gaw, p.obs_gaw) and q.prior == p.prior and q.config == p.config
    import pickle

    r = pickle.loads(pickle.dumps(p))
    assert r.window == p.window and r.sigma_e == 1.5


def test_unknown_name_and_lo_hi_fail_before_any_simulation(obs_gaw):
    sim = Counting()
    with pytest.raises(ValueError, match="unknown parameter"):
        importance_sample(Problem(obs_gaw, 2000.0, Prior({"E_bdy": (9, 15)})), n=10)
    with pytest.raises(ValueError, match="lo < hi"):
        Problem(obs_gaw, 2000.0, Prior({"E_body": (15, 9)}))
    assert sim.calls == 0


def test_noisy_synthetic_still_valid():
    validate_observation(synthetic_gaw(noise=1.0), 2000.0)
