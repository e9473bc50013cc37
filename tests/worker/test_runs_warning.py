"""A single SMC run of the six scaled parameters is warned about (it cannot see a basin it missed); several runs,
fewer free parameters or importance sampling are not (worker.reduce.runs_warning)."""

from __future__ import annotations

import numpy as np
import pytest
import toy_model  # noqa: F401  (registers model "toy")

from worker.jobspec import JobSpec
from worker.reduce import runs_warning

SIX = {
    "E_body": [9.0, 15.0],
    "E_cover": [250.0, 950.0],
    "E_lig": [1.0, 3.0],
    "p_sub": [400.0, 1800.0],
    "rho": [1000.0, 1100.0],
    "eta": [1.0, 5.0],
}
TABLE3 = {"E_body": 12.0, "E_cover": 636.2, "E_lig": 1.808, "p_sub": 990.0, "rho": 1051.0, "eta": 3.079, "x0": 8.4}


def _spec(free: list[str], sampler: dict) -> JobSpec:
    t = np.arange(800) / 4000.0
    return JobSpec.model_validate(
        {
            "model": "toy",
            "gaw": {"areas": (10.0 * (1 - np.cos(2 * np.pi * 70.0 * t))).tolist(), "fps": 4000.0},
            "priors": {n: SIX[n] for n in free},
            "fixed": {n: v for n, v in TABLE3.items() if n not in free},
            "sampler": sampler,
            "duration": 0.35,
            "discard": 0.2,
            "sigma_e": 1.0,
            "seed": 0,
        }
    )


@pytest.mark.parametrize(
    "free, sampler, warned",
    [
        (list(SIX), {"kind": "smc", "n_particles": 20}, True),
        (list(SIX), {"kind": "smc", "n_particles": 20, "runs": 3}, False),
        (["E_body", "E_cover", "p_sub"], {"kind": "smc", "n_particles": 20}, False),
        (list(SIX), {"kind": "is", "n_samples": 20}, False),
    ],
)
def test_one_run_of_six_free_parameters_is_warned(free, sampler, warned):
    w = runs_warning(_spec(free, sampler))
    if warned:
        assert w.startswith("ONE RUN:") and "--runs 3" in w
    else:
        assert w is None
