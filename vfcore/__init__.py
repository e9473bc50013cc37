"""vfcore: a 2D finite-element vocal-fold forward model and Bayesian inference of its parameters."""

from .config import MESHES, SimConfig
from .forward import simulate, simulate_batch
from .params import PARAM_NAMES, PARAM_UNITS, TABLE3, Params
from .result import CycleSummary, SimResult

__all__ = [
    "MESHES",
    "SimConfig",
    "PARAM_NAMES",
    "PARAM_UNITS",
    "TABLE3",
    "Params",
    "CycleSummary",
    "SimResult",
    "simulate",
    "simulate_batch",
]
