"""TEST DOUBLE: a cheap analytic stand-in for the finite-element forward model, registered as ``model="toy"``.

This is *not* physics. Importing this module registers it with ``worker.models`` as a test double, which
the service accepts only when started with ``allow_toy_model`` (tests, benchmarks of the distributed
machinery); a process of its own loads it through :data:`PLUGIN_ENV` (``VFINFER_MODEL_PLUGINS=toy_model``
with this folder on its ``PYTHONPATH``). It maps the
seven parameters to a smooth half-rectified, slowly growing sinusoid (a "damped oscillator"
GAW) so the queue, store, fault-tolerance and resume logic can be exercised in milliseconds
per simulation.  Scoring (alignment window, Gaussian log-likelihood) is vfcore's, so the
worker code path is identical to the FE one apart from the function that makes a GAW.
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from vfcore.inference.problem import Evaluation, Problem, n_sim_frames
from vfcore.params import PARAM_NAMES, TABLE3
from worker.models import register_model

_HERE = Path(__file__).resolve().parent

#: Environment of a process of its own (``vfinfer serve``, a Dask worker) that must know this model: the
#: registry imports ``toy_model`` on its first look-up, and unpickling the evaluator imports it too. The
#: repository comes first on the path so that the test folders never shadow the packages.
PLUGIN_ENV = {
    "PYTHONPATH": os.pathsep.join(p for p in (str(_HERE.parents[1]), str(_HERE), os.environ.get("PYTHONPATH")) if p),
    "VFINFER_MODEL_PLUGINS": "toy_model",
}


class ToyOptions(BaseModel):
    """``model_options`` of a ``model="toy"`` job."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    delay_s: float = Field(default=0.0, ge=0, le=5.0, description="artificial cost per simulation, s")


def toy_gaw(full_params: np.ndarray, fps: float, n_frames: int) -> tuple[np.ndarray, float, float, float]:
    """Analytic GAW (mm^2) for one full 7-vector in PARAM_NAMES order.

    Returns (gaw, mean_flow m^3/s, mean_contact Pa, max_contact Pa) - all made-up but smooth.
    """
    p = dict(zip(PARAM_NAMES, np.asarray(full_params, dtype=float)))
    ref = TABLE3.as_dict()
    f0 = (
        110.0
        * math.sqrt(p["E_cover"] / ref["E_cover"])
        * (p["E_body"] / ref["E_body"]) ** 0.25
        * math.sqrt(ref["rho"] / p["rho"])
        * (p["E_lig"] / ref["E_lig"]) ** 0.1
    )
    amp = 12.0 * math.sqrt(max(p["p_sub"], 0.0) / ref["p_sub"]) * (1.0 + 0.5 * (8.4 - p["x0"]))
    tau = 0.02 * p["eta"] / ref["eta"]
    t = np.arange(n_frames) / fps
    s = np.sin(2 * math.pi * f0 * t)
    gaw = amp * np.maximum(s, 0.0) ** 1.5 * (1.0 - 0.3 * np.exp(-t / tau))
    flow = 1e-4 * float(np.mean(gaw)) * math.sqrt(max(p["p_sub"], 0.0) / 1000.0)
    contact = 50.0 * p["E_cover"] / ref["E_cover"] * (p["p_sub"] / ref["p_sub"])
    return gaw, flow, contact, 3.0 * contact


class ToyEvaluator:
    """Picklable ``thetas (k, d) -> Evaluation`` with the same contract as vfcore's ``evaluate``."""

    def __init__(self, problem: Problem, delay_s: float = 0.0):
        self.problem = problem
        self.delay_s = float(delay_s)

    def __call__(self, thetas) -> Evaluation:
        pb = self.problem
        thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
        k = thetas.shape[0]
        max_lag, n_cmp = pb.window
        n = n_sim_frames(pb.config)
        full = pb.prior.full_array(thetas) if k else np.empty((0, len(PARAM_NAMES)))
        ll = np.full(k, -np.inf)
        ok = np.zeros(k, bool)
        gaw = np.full((k, n_cmp), np.nan, dtype=np.float32)
        flow, cmean, cmax = (np.full(k, np.nan) for _ in range(3))
        for i in range(k):
            if self.delay_s:
                time.sleep(self.delay_s)
            g, flow[i], cmean[i], cmax[i] = toy_gaw(full[i], pb.fps, n)
            seg = pb.align(g)
            ll[i] = pb.loglik(seg, full[i])
            ok[i] = True
            gaw[i] = seg
        return Evaluation(loglik=ll, ok=ok, gaw=gaw, mean_flow=flow, mean_contact=cmean, max_contact=cmax)


def toy_observation(
    params: dict | None = None, fps: float = 4000.0, duration: float = 0.1, noise: float = 0.0, seed: int = 0
) -> list[float]:
    """A GAW made by the toy model (for tests), optionally with Gaussian noise (mm^2)."""
    full = TABLE3.as_array().copy()
    for k, v in (params or {}).items():
        full[PARAM_NAMES.index(k)] = v
    n = int(round(duration * fps))
    g, *_ = toy_gaw(full, fps, n)
    if noise:
        g = g + np.random.default_rng(seed).normal(0.0, noise, g.size)
    return np.maximum(g, 0.0).tolist()


def _evaluator(spec, problem: Problem) -> ToyEvaluator:
    return ToyEvaluator(problem, spec.model_options["delay_s"])


def _seconds_per_sim(spec) -> float:
    return spec.model_options["delay_s"] + 2e-4


register_model("toy", _evaluator, _seconds_per_sim, ToyOptions, test_double=True)
