"""Batched forward simulation: blocks of parameter vectors advanced in lock-step.

``simulate_many(params_array, config, block)`` returns the same SimResults as calling
:func:`vfcore.forward.simulate` on each row (per-sample arithmetic follows the scalar
kernel operation for operation), but the CSR products and triangular solves of a block run
with the sample index innermost (SIMD across samples).

Rows may carry their own configurations (``configs=``): rows whose configurations differ
only in the model extensions (separation ratio, epithelium membrane, subglottal resonators)
share a block; the extensions are per-sample data of the lock-step kernel.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from .config import SimConfig
from .params import PARAM_NAMES, Params
from .result import SimResult
from .simcore import (BLOWUP, CLOSED_TOL, as_params, assemble_result, contact_law, flow_coefficient, midline, setup,
                      stop_settings)
from .solver import _kernels as kern
from .solver._batch_kernels import integrate_many
from .solver.system import get_system

#: SimConfig fields that may differ between the rows of one lock-step block.
PER_SAMPLE_FIELDS = ("sep_ratio", "epithelium_E_kpa", "epithelium_h_mm", "epithelium_profile", "subglottal_modes")


def _as_rows(params) -> np.ndarray:
    if isinstance(params, np.ndarray):
        arr = np.atleast_2d(np.asarray(params, dtype=float))
        if arr.shape[1] != len(PARAM_NAMES):
            raise ValueError(f"params must have shape (n, {len(PARAM_NAMES)}), got {arr.shape}")
        return arr
    return np.array([as_params(x).as_array() for x in params]).reshape(-1, len(PARAM_NAMES))


def block_key(config: SimConfig) -> SimConfig:
    """The part of ``config`` that rows of one block must share (extensions reset to defaults)."""
    d = SimConfig()
    return dataclasses.replace(config, **{f: getattr(d, f) for f in PER_SAMPLE_FIELDS})


def _simulate_block(ps: list[Params], configs: list[SimConfig]) -> list[SimResult]:
    t_wall = time.perf_counter()
    config = configs[0]
    system = get_system(config.mesh, config.nu, config.element)
    B = len(ps)
    n, m, nnz, nl = system.n, system.sdx.size, system.indices.size, system.nnz_factor
    h = config.dt
    n_steps = int(round(config.duration / h))
    am, af, beta, gamma = kern.newmark_coefficients(h, config.rho_inf)
    kv = np.empty((nnz, B))
    mv = np.empty((nnz, B))
    dv = np.empty((nnz, B))
    Lx = np.empty((nl, B))
    G = np.empty((B, n, m))
    u = np.empty((n, B))
    x_mid = np.empty(B)
    p_sub = np.empty(B)
    sep = np.empty(B)
    coefs = [kern.subglottal_coefficients(c.subglottal_modes, h) for c in configs]
    nmod = max(c.shape[0] for c in coefs)
    sub_coef = np.zeros((B, nmod, 3))            # zero rows: resonators that add exactly 0 Pa
    kc = np.empty((B, m))
    cc = np.empty((B, m))
    for b, p in enumerate(ps):
        kc[b], cc[b] = contact_law(p, configs[b], system)
        # exactly the per-sample set-up of forward.simulate (both call vfcore.simcore)
        x_mid[b] = midline(p, configs[b])
        p_sub[b] = p.si()["p_sub"]
        sep[b] = configs[b].sep_ratio
        kv[:, b], dv[:, b], mv[:, b], u[:, b], Lx[:, b], G[b] = setup(p, configs[b], system)
        sub_coef[b, : coefs[b].shape[0]] = coefs[b]
    v = np.zeros((n, B))
    a = np.zeros((n, B))
    width = np.zeros((B, n_steps))
    gsep = np.zeros((B, n_steps))
    lam = np.zeros((B, n_steps, m))
    p_in = np.repeat(p_sub[:, None], n_steps, axis=1) if nmod > 0 else np.zeros((B, 0))
    traj_every = 0
    n_traj = 0
    if config.keep_trajectories:
        traj_every = max(1, int(round(1.0 / (config.fps * h))))
        n_traj = n_steps // traj_every
    tu = np.zeros((B, n_traj, n))
    tv = np.zeros((B, n_traj, n))
    status = np.zeros(B, dtype=np.int64)
    proj = np.zeros((B, n_steps, m))
    stop = np.zeros(B, dtype=np.int64)
    integrate_many(n_steps, h, am, af, beta, gamma, system.indptr, system.indices, kv, mv, dv, system.Lp, system.Lj,
                   Lx, G, system.sdx, system.sdz, system.sX, system.sZ, u, v, a, p_sub, config.p_sup, sep,
                   x_mid, CLOSED_TOL, config.closure_gap_mm * 1e-3, BLOWUP, width, gsep, lam, traj_every, tu, tv,
                   status, sub_coef, flow_coefficient(config), p_in, proj, config.contact == "layer", kc, cc,
                   *stop_settings(config), stop)
    t_each = (time.perf_counter() - t_wall) / B
    out = []
    for b, p in enumerate(ps):
        t0 = time.perf_counter() - t_each   # wall_time: this sample's share of the block
        out.append(assemble_result(p, configs[b], system, int(status[b]), width[b], gsep[b], lam[b], traj_every,
                                   tu[b], t0, p_in[b] if configs[b].has_subglottal else None, proj[b], int(stop[b])))
    return out


def simulate_many(params_array, config: SimConfig | None = None, block: int = 32,
                  configs=None) -> list[SimResult]:
    """Simulate each row of ``params_array`` ((N, 7), ``PARAM_NAMES`` order, paper units).

    Rows are advanced ``block`` at a time in lock-step; results equal ``simulate`` row by
    row (a sample that blows up gets ``ok=False`` without stopping its block).

    ``configs`` (optional, one SimConfig per row) overrides ``config`` row by row. Rows are
    grouped by :func:`block_key` (everything but the extensions in ``PER_SAMPLE_FIELDS``) and each
    group is simulated in blocks; the results come back in row order.
    """
    arr = _as_rows(params_array)
    if block < 1:
        raise ValueError(f"block must be >= 1, got {block}")
    ps = [Params.from_array(r) for r in arr]
    if configs is None:
        configs = [config or SimConfig()] * len(ps)
    else:
        configs = list(configs)
        if len(configs) != len(ps):
            raise ValueError(f"configs must have one SimConfig per row: {len(configs)} configs for {len(ps)} rows")
        if not all(isinstance(c, SimConfig) for c in configs):
            raise ValueError("configs must be SimConfig instances")
    groups: dict[SimConfig, list[int]] = {}
    for i, c in enumerate(configs):
        groups.setdefault(block_key(c), []).append(i)
    out: list[SimResult | None] = [None] * len(ps)
    for idx in groups.values():
        for s in range(0, len(idx), block):
            sel = idx[s:s + block]
            for i, r in zip(sel, _simulate_block([ps[i] for i in sel], [configs[i] for i in sel])):
                out[i] = r
    return out  # type: ignore[return-value]
