"""Twin experiments: synthetic observations from the forward model at known parameters.

The truth is drawn uniformly inside the prior; the model is simulated at the inference's own
``SimConfig`` (which downsamples to the camera rate, 2000 fps by default); a window of
``n_obs`` frames starting at ``offset`` (so the alignment has to find the phase) gets
independent Gaussian noise of standard deviation ``sigma_e``. Truths at which the model
fails or does not phonate (the observation would be rejected by ``validate_observation``)
are redrawn: the inference presupposes a recording of an oscillating fold.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..config import SimConfig
from .prior import Prior
from .problem import Problem, validate_observation


@dataclass(frozen=True, eq=False)
class Twin:
    truth: np.ndarray  # (d,) estimated parameters, prior.names order
    problem: Problem
    clean_gaw: np.ndarray  # noise-free observed window
    n_redraws: int  # truths rejected (failed / not phonating)

    @property
    def truth_dict(self) -> dict[str, float]:
        return dict(zip(self.problem.prior.names, map(float, self.truth)))


def make_twin(
    prior: Prior,
    config: SimConfig,
    seed: int,
    *,
    sigma_e: float = 1.0,
    n_obs: int = 400,
    offset: int = 7,
    truth=None,
    simulate_fn: Callable | None = None,
    max_tries: int = 50,
) -> Twin:
    """Build a twin data set and its Problem (deterministic in ``seed``)."""
    if simulate_fn is None:
        from vfcore.forward import simulate as simulate_fn
    ss = np.random.SeedSequence(seed)
    rng_truth, rng_noise = (np.random.default_rng(s) for s in ss.spawn(2))
    redraws = 0
    for _ in range(max_tries):
        theta = np.asarray(truth, dtype=float) if truth is not None else prior.sample(1, rng_truth)[0]
        r = simulate_fn(prior.to_params(theta), config)
        if r.ok and r.gaw.size >= offset + n_obs:
            clean = np.asarray(r.gaw[offset : offset + n_obs], dtype=float)
            y = clean + sigma_e * rng_noise.standard_normal(n_obs)
            try:
                validate_observation(clean, config.fps)
                problem = Problem(y, config.fps, prior, sigma_e=sigma_e, config=config)
            except ValueError:
                pass
            else:
                return Twin(truth=theta, problem=problem, clean_gaw=clean, n_redraws=redraws)
        if truth is not None:
            raise ValueError(f"the model does not phonate at the given truth {theta} ({r.message})")
        redraws += 1
    raise RuntimeError(f"no phonating truth found in {max_tries} prior draws")
