"""The scalar forward kernel for one parameter vector: what :func:`vfcore.forward.simulate` runs, and what
:func:`vfcore.batch.simulate_many` runs for blocks too small for the lock-step kernel (both sit above this module,
so neither imports the other)."""

from __future__ import annotations

import time

import numpy as np

from .config import SimConfig
from .params import Params
from .result import SimResult
from .simcore import (
    BLOWUP,
    CLOSED_TOL,
    assemble_result,
    contact_law,
    flow_code,
    flow_coefficient,
    midline,
    setup,
    stop_settings,
)
from .solver import _kernels as kern
from .solver._args import Coupling, Matrices, Model, Outputs, Pattern, State, Stepper, Stop
from .solver.system import get_system

__all__ = ["simulate_one"]


def simulate_one(p: Params, config: SimConfig) -> SimResult:
    """One forward simulation of ``p`` under ``config`` (see :func:`vfcore.forward.simulate`)."""
    t_wall = time.perf_counter()
    system = get_system(config.mesh, config.nu, config.element)
    si = p.si()
    h = config.dt
    n_steps = int(round(config.duration / h))
    x_mid = midline(p, config)

    K_vals, D_vals, M_vals, u, Lx, G = setup(p, config, system)
    v = np.zeros(system.n)
    a = np.zeros(system.n)
    m = system.sdx.size
    width = np.zeros(n_steps)
    gsep = np.zeros(n_steps)
    lam = np.zeros((n_steps, m))
    traj_every = 0
    n_traj = 0
    if config.keep_trajectories:
        traj_every = max(1, int(round(1.0 / (config.fps * h))))
        n_traj = n_steps // traj_every
    tu = np.zeros((n_traj, system.n))
    tv = np.zeros((n_traj, system.n))
    am, af, beta, gamma = kern.newmark_coefficients(h, config.rho_inf)
    proj = np.zeros((n_steps, m))
    stop = np.zeros(1, dtype=np.int64)
    # no resonator rows: exactly kern.integrate (the inlet pressure stays p_sub)
    p_in = np.full(n_steps, si["p_sub"]) if config.has_subglottal else np.zeros(0)
    status = kern.integrate_coupled(
        Stepper(n_steps, h, am, af, beta, gamma),
        Pattern(system.indptr, system.indices, system.Lp, system.Lj, system.sdx, system.sdz, system.sX, system.sZ),
        Model(
            si["p_sub"],
            config.p_sup,
            config.sep_ratio,
            x_mid,
            CLOSED_TOL,
            config.closure_gap_mm * 1e-3,
            flow_code(config),
            BLOWUP,
        ),
        Coupling(
            kern.subglottal_coefficients(config.subglottal_modes, h),
            flow_coefficient(config),
            config.contact == "layer",
            *contact_law(p, config, system),
        ),
        Stop(*stop_settings(config)),
        Matrices(K_vals, M_vals, D_vals, Lx, G),
        State(u, v, a),
        Outputs(width, gsep, lam, proj, p_in, traj_every, tu, tv, stop),
    )
    return assemble_result(
        p,
        config,
        system,
        status,
        width,
        gsep,
        lam,
        traj_every,
        tu,
        t_wall,
        p_in if config.has_subglottal else None,
        proj,
        int(stop[0]),
    )
