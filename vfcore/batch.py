"""Batched forward simulation: blocks of parameter vectors advanced in lock-step.

``simulate_many(params_array, config, block)`` returns the same SimResults as calling
:func:`vfcore.forward.simulate` on each row (per-sample arithmetic follows the scalar
kernel operation for operation), but the CSR products and band solves of a block run
with the sample index innermost (SIMD across samples).
"""
from __future__ import annotations

import time

import numpy as np

from .config import SimConfig
from .forward import BLOWUP, CLOSED_TOL, _params, _result, midline, prestress, simulate
from .params import PARAM_NAMES, Params
from .result import SimResult
from .solver import _kernels as kern
from .solver._batch_kernels import integrate_many
from .solver.system import get_system


def _as_rows(params) -> np.ndarray:
    if isinstance(params, np.ndarray):
        arr = np.atleast_2d(np.asarray(params, dtype=float))
        if arr.shape[1] != len(PARAM_NAMES):
            raise ValueError(f"params must have shape (n, {len(PARAM_NAMES)}), got {arr.shape}")
        return arr
    return np.array([_params(x).as_array() for x in params]).reshape(-1, len(PARAM_NAMES))


def _simulate_block(ps: list[Params], config: SimConfig) -> list[SimResult]:
    t_wall = time.perf_counter()
    system = get_system(config.mesh, config.nu, config.element)
    B = len(ps)
    n, m, nnz = system.n, system.sdx.size, system.indices.size
    h = config.dt
    n_steps = int(round(config.duration / h))
    cM, cD, cK = kern.effective_scales(h, config.rho_inf)
    am, af, beta, gamma = kern.newmark_coefficients(h, config.rho_inf)
    kv = np.empty((nnz, B))
    mv = np.empty((nnz, B))
    dv = np.empty((nnz, B))
    Lb = np.empty((n, system.bw + 1, B))
    G = np.empty((B, n, m))
    u = np.empty((n, B))
    x_mid = np.empty(B)
    p_sub = np.empty(B)
    for b, p in enumerate(ps):
        # exactly the per-sample set-up of forward.simulate
        si = p.si()
        x_mid[b] = midline(p, config)
        p_sub[b] = si["p_sub"]
        K_vals = system.stiffness_values((si["E_body"], si["E_lig"], si["E_cover"]))
        u[:, b], _ = prestress(system, K_vals, x_mid[b])
        eff = cK * K_vals + cD * si["eta"] * system.d_vals + cM * si["rho"] * system.m_vals
        Lb1 = system.factor(eff)
        Lb[:, :, b] = Lb1
        G[b] = system.contact_columns(Lb1)
        kv[:, b] = K_vals
        mv[:, b] = si["rho"] * system.m_vals
        dv[:, b] = si["eta"] * system.d_vals
    v = np.zeros((n, B))
    a = np.zeros((n, B))
    width = np.zeros((B, n_steps))
    gsep = np.zeros((B, n_steps))
    lam = np.zeros((B, n_steps, m))
    traj_every = 0
    n_traj = 0
    if config.keep_trajectories:
        traj_every = max(1, int(round(1.0 / (config.fps * h))))
        n_traj = n_steps // traj_every
    tu = np.zeros((B, n_traj, n))
    tv = np.zeros((B, n_traj, n))
    status = np.zeros(B, dtype=np.int64)
    integrate_many(n_steps, h, am, af, beta, gamma, system.indptr, system.indices, kv, mv, dv, Lb, G,
                   system.sdx, system.sdz, system.sX, system.sZ, u, v, a, p_sub, config.p_sup, config.sep_ratio,
                   x_mid, CLOSED_TOL, config.closure_gap_mm * 1e-3, BLOWUP, width, gsep, lam, traj_every, tu, tv,
                   status)
    t_each = (time.perf_counter() - t_wall) / B
    out = []
    for b, p in enumerate(ps):
        t0 = time.perf_counter() - t_each   # wall_time: this sample's share of the block
        out.append(_result(p, config, system, int(status[b]), width[b], gsep[b], lam[b], traj_every, tu[b], t0))
    return out


def simulate_many(params_array, config: SimConfig | None = None, block: int = 8) -> list[SimResult]:
    """Simulate each row of ``params_array`` ((N, 7), ``PARAM_NAMES`` order, paper units).

    Rows are advanced ``block`` at a time in lock-step; results equal ``simulate`` row by
    row (a sample that blows up gets ``ok=False`` without stopping its block).

    The lock-step kernel does not implement the forward-model extensions: when
    ``config.has_extensions`` (epithelium membrane or subglottal coupling) each row is
    simulated with the scalar :func:`vfcore.forward.simulate` instead (same results, no
    batching speed-up).
    """
    config = config or SimConfig()
    arr = _as_rows(params_array)
    if block < 1:
        raise ValueError(f"block must be >= 1, got {block}")
    ps = [Params.from_array(r) for r in arr]
    if config.has_extensions:
        return [simulate(p, config) for p in ps]
    out: list[SimResult] = []
    for s in range(0, len(ps), block):
        out.extend(_simulate_block(ps[s:s + block], config))
    return out
