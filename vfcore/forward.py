"""Public face of the forward model: ``simulate(params, config) -> SimResult``.

Hadwin et al. (2019), Sections 3 and 4.1; every choice is documented in :ref:`model`. The scalar kernel's
driver is :mod:`vfcore.scalar`; the set-up and result assembly live in :mod:`vfcore.simcore`, shared with the
lock-step :mod:`vfcore.batch`; the constants and steps are re-exported here, where callers read them as
``vfcore.forward.X``.
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor

import numpy as np

from . import batch
from .config import SimConfig
from .params import PARAM_NAMES
from .result import SimResult
from .scalar import simulate_one
from .simcore import (
    BLOWUP,
    CLOSED_TOL,
    MIN_CYCLE_AMPLITUDE,
    RHO_AIR,
    STOP_VEL,
    STOP_WIDTH,
    STOP_WINDOW_S,
    as_params,
    assemble_result,
    contact_law,
    cycle_summary,
    flow_coefficient,
    midline,
    prestress,
    setup,
    stop_settings,
)

__all__ = [
    "simulate",
    "simulate_batch",
    "BLOWUP",
    "CLOSED_TOL",
    "MIN_CYCLE_AMPLITUDE",
    "RHO_AIR",
    "STOP_VEL",
    "STOP_WIDTH",
    "STOP_WINDOW_S",
    "as_params",
    "assemble_result",
    "contact_law",
    "cycle_summary",
    "flow_coefficient",
    "midline",
    "prestress",
    "setup",
    "stop_settings",
]


def simulate(params, config: SimConfig | None = None) -> SimResult:
    """Run one forward simulation.

    Parameters
    ----------
    params : Params, dict or array in ``PARAM_NAMES`` order, paper units
        (E_body kPa, E_cover Pa, E_lig kPa, p_sub Pa, rho kg/m^3, eta Poise, x0 mm).
    config : SimConfig (numerics, observation).

    Returns
    -------
    SimResult at the camera rate over [discard, duration]. A simulation whose state
    becomes non-finite (or exceeds 1 cm) is returned with ``ok=False``, never as NaNs.
    """
    return simulate_one(as_params(params), config or SimConfig())


def _simulate_rows(args):
    rows, config, block = args
    # simulate_many runs blocks under MIN_LOCKSTEP rows, block 1 included, through the scalar kernel
    return batch.simulate_many(rows, config, block=max(1, block))


def simulate_batch(
    params, config: SimConfig | None = None, n_workers: int = 1, block: int = batch.LOCKSTEP_WIDTH
) -> list[SimResult]:
    """Simulate many parameter vectors.

    params : (n, 7) array in ``PARAM_NAMES`` order (paper units), or a list of Params.
    n_workers : processes to spread the batch over (1 = in this process). Each process
    runs numba single-threaded (one level of parallelism at a time).
    block : lock-step block size within a process (:func:`vfcore.batch.simulate_many`, SIMD
    across samples); 1 = one scalar :func:`simulate` per row.
    """
    config = config or SimConfig()
    if isinstance(params, np.ndarray):
        arr = np.atleast_2d(np.asarray(params, dtype=float))
        if arr.shape[1] != len(PARAM_NAMES):
            raise ValueError(f"params must have shape (n, {len(PARAM_NAMES)}), got {arr.shape}")
    else:
        arr = np.array([as_params(x).as_array() for x in params])
    if n_workers <= 1 or len(arr) < 2:
        return _simulate_rows((arr, config, block))
    chunks = [c for c in np.array_split(arr, n_workers) if len(c)]
    with ProcessPoolExecutor(n_workers) as ex:
        out = list(ex.map(_simulate_rows, [(c, config, block) for c in chunks]))
    return [r for part in out for r in part]
