"""The forward models a job may name (``JobSpec.model``): a small registry.

The product registers one model, ``"fe"`` (vfcore's finite-element model). Another model -- for example an
analytic stand-in that lets tests exercise the queue, the store and resume in milliseconds per simulation --
is plugged in with :func:`register_model` by the code that needs it. A process started on its own (a
``vfinfer serve`` under test, a Dask worker) loads such models from the modules named in
``VFINFER_MODEL_PLUGINS`` (comma-separated, imported on the first look-up), so the product itself never
imports them.
"""

from __future__ import annotations

import importlib
import os
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

#: Environment variable naming the modules (comma-separated) that register further models when imported.
PLUGINS_ENV = "VFINFER_MODEL_PLUGINS"

#: Single-core seconds per time step of the FE model, per mesh (sizing only), measured on the
#: 2-core CI machine with the JIT warm: coarse 0.062 s (dt=1e-4, 0.45 s), medium 0.125 s (dt=5e-5, 0.4 s).
FE_SECONDS_PER_STEP = {"coarse": 1.4e-5, "medium": 1.6e-5, "fine": 2.1e-5}


@dataclass(frozen=True)
class Model:
    """One registered forward model.

    ``evaluator(spec, problem)`` makes the picklable batch function ``thetas (k, d) -> Evaluation`` that the
    worker maps over chunks; ``seconds_per_sim(spec)`` estimates one simulation's single-core cost (chunk
    sizing only); ``options_type`` (a pydantic model, or ``None``) validates the spec's ``model_options``;
    a ``test_double`` is refused by the service unless its settings allow test doubles.
    """

    name: str
    evaluator: Callable[[Any, Any], Callable]
    seconds_per_sim: Callable[[Any], float]
    options_type: type | None = None
    test_double: bool = False


_MODELS: dict[str, Model] = {}
_lock = threading.Lock()
_plugins_loaded = False


def register_model(
    name: str,
    evaluator: Callable[[Any, Any], Callable],
    seconds_per_sim: Callable[[Any], float],
    options_type: type | None = None,
    *,
    test_double: bool = False,
) -> Model:
    """Make ``name`` a valid ``JobSpec.model`` (see :class:`Model` for the arguments); registering a name
    again replaces its entry, so a module imported twice (pytest and a plugin list) stays harmless."""
    model = Model(name, evaluator, seconds_per_sim, options_type, test_double)
    with _lock:
        _MODELS[name] = model
    return model


def _load_plugins() -> None:
    global _plugins_loaded
    if _plugins_loaded:
        return
    _plugins_loaded = True
    for module in (m.strip() for m in os.environ.get(PLUGINS_ENV, "").split(",")):
        if module:
            importlib.import_module(module)


def model_names() -> tuple[str, ...]:
    """The registered models' names, ``"fe"`` first."""
    _load_plugins()
    with _lock:
        return tuple(sorted(_MODELS, key=lambda n: (n != "fe", n)))


def model_named(name: str) -> Model:
    """The registered model ``name``; ValueError naming the known ones otherwise."""
    _load_plugins()
    with _lock:
        model = _MODELS.get(name)
    if model is None:
        raise ValueError(f"unknown model {name!r}; known: {list(model_names())}")
    return model


def job_device(spec) -> str:
    """The job's forward-model device ("cpu", "cuda" or "auto"; "cpu" for a spec without the field)."""
    return getattr(spec, "device", None) or "cpu"


def fe_evaluator(spec, problem):
    """vfcore's finite-element model on the job's device."""
    if job_device(spec) != "cpu":
        from vfcore.inference.device_eval import DeviceEvaluator

        return DeviceEvaluator(problem, job_device(spec))
    from vfcore.inference.scoring import ProblemEvaluator

    return ProblemEvaluator(problem)


def fe_seconds_per_sim(spec) -> float:
    return (spec.duration / spec.dt) * FE_SECONDS_PER_STEP[spec.mesh]


register_model("fe", fe_evaluator, fe_seconds_per_sim)
