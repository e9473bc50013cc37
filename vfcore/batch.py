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
from .scalar import simulate_one
from .simcore import (
    BLOWUP,
    CLOSED_TOL,
    as_params,
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
from .solver._batch_kernels import integrate_many
from .solver.system import get_system

#: Blocks of fewer rows than this run through the scalar kernel (:func:`.scalar.simulate_one`), which gives the
#: same bits: the lock-step kernel's sample loops cost more than they share at a few samples. Coarse mesh, dt 1e-4 s,
#: one core beside a busy one, time per simulation against the scalar kernel's: block 1 2.2x, 2 1.5x, 3 1.1x, 4 1.1x,
#: 6 0.90x, 16 0.63x (``benchmarks/bench_batch.py --mesh coarse --dt 1e-4 --n 12``; three runs put blocks 3 and 4
#: at 1.06-1.41x, the medium mesh at dt 5e-5 s alike). Single rows are what a Nelder-Mead polish evaluates.
MIN_LOCKSTEP = 5

#: Default rows per lock-step block. A generation cut into equal parts per worker gives parts of 40-50 rows, and in
#: blocks of 32 those run as a full block and a narrow one: ``benchmarks/bench_block_width.py`` (rows near Table 3,
#: one core, medians of 3; medium mesh, dt 5e-5 s): 40 rows in one block 1.99 s against 2.49 s as 2 x 20, 48 rows
#: 2.41 against 2.74 s, 50 rows 2.89 against 3.44 s as 32 + 18. At 64 rows and beyond one block and two halves
#: cost the same (64: 3.65 against 3.54 s; 100: 5.77 against 5.61 s; coarse mesh at dt 1e-4 s, 64 rows 1.32
#: against 1.39 s, 100 rows 2.18 against 2.45 s), so 64 is as wide as a block needs to be. The blocking changes no
#: result (the same bits as the scalar kernel, row by row).
LOCKSTEP_WIDTH = 64

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


@dataclasses.dataclass
class BlockInputs:
    """Host-side inputs of one block (CPU lock-step layout, sample index last except ``G``): the set-up every
    backend shares, from :func:`prepare_block`."""

    system: object
    config: SimConfig  # the block's shared numerics (configs[0])
    n_steps: int
    coefs: tuple  # (am, af, beta, gamma)
    kv: np.ndarray  # (nnz, B)
    mv: np.ndarray
    dv: np.ndarray
    Lx: np.ndarray  # (nnz_L, B)
    G: np.ndarray  # (B, n, m)
    u: np.ndarray  # (n, B)
    x_mid: np.ndarray  # (B,)
    p_sub: np.ndarray
    sep: np.ndarray
    sub_coef: np.ndarray  # (B, n_modes, 3)
    kc: np.ndarray  # (B, m)
    cc: np.ndarray
    traj_every: int
    n_traj: int


def prepare_block(ps: list[Params], configs: list[SimConfig]) -> BlockInputs:
    """Per-sample set-up of a block: exactly that of ``forward.simulate`` (both call :mod:`vfcore.simcore`)."""
    config = configs[0]
    system = get_system(config.mesh, config.nu, config.element)
    B = len(ps)
    n, m, nnz, nl = system.n, system.sdx.size, system.indices.size, system.nnz_factor
    h = config.dt
    n_steps = int(round(config.duration / h))
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
    sub_coef = np.zeros((B, nmod, 3))  # zero rows: resonators that add exactly 0 Pa
    kc = np.empty((B, m))
    cc = np.empty((B, m))
    for b, p in enumerate(ps):
        kc[b], cc[b] = contact_law(p, configs[b], system)
        x_mid[b] = midline(p, configs[b])
        p_sub[b] = p.si()["p_sub"]
        sep[b] = configs[b].sep_ratio
        kv[:, b], dv[:, b], mv[:, b], u[:, b], Lx[:, b], G[b] = setup(p, configs[b], system)
        sub_coef[b, : coefs[b].shape[0]] = coefs[b]
    traj_every = 0
    n_traj = 0
    if config.keep_trajectories:
        traj_every = max(1, int(round(1.0 / (config.fps * h))))
        n_traj = n_steps // traj_every
    return BlockInputs(
        system,
        config,
        n_steps,
        kern.newmark_coefficients(h, config.rho_inf),
        kv,
        mv,
        dv,
        Lx,
        G,
        u,
        x_mid,
        p_sub,
        sep,
        sub_coef,
        kc,
        cc,
        traj_every,
        n_traj,
    )


def assemble_block(
    blk: BlockInputs,
    ps: list[Params],
    configs: list[SimConfig],
    status,
    width,
    gsep,
    lam,
    tu,
    p_in,
    proj,
    stop,
    t_wall: float,
) -> list[SimResult]:
    """SimResults of a block from its per-sample outputs, indexed ``[b]`` (``lam[b]`` (n_steps, m), ``p_in[b]``
    (n_steps,) when the block has subglottal modes); ``t_wall``: the block's start (perf_counter)."""
    t_each = (time.perf_counter() - t_wall) / len(ps)
    out = []
    for b, p in enumerate(ps):
        t0 = time.perf_counter() - t_each  # wall_time: this sample's share of the block
        out.append(
            assemble_result(
                p,
                configs[b],
                blk.system,
                int(status[b]),
                width[b],
                gsep[b],
                lam[b],
                blk.traj_every,
                tu[b],
                t0,
                p_in[b] if configs[b].has_subglottal else None,
                proj[b],
                int(stop[b]),
            )
        )
    return out


def _simulate_block(ps: list[Params], configs: list[SimConfig]) -> list[SimResult]:
    t_wall = time.perf_counter()
    blk = prepare_block(ps, configs)
    config, system, n_steps = blk.config, blk.system, blk.n_steps
    B = len(ps)
    n, m = system.n, system.sdx.size
    nmod = blk.sub_coef.shape[1]
    v = np.zeros((n, B))
    a = np.zeros((n, B))
    width = np.zeros((B, n_steps))
    gsep = np.zeros((B, n_steps))
    lam = np.zeros((B, n_steps, m))
    p_in = np.repeat(blk.p_sub[:, None], n_steps, axis=1) if nmod > 0 else np.zeros((B, 0))
    tu = np.zeros((B, blk.n_traj, n))
    tv = np.zeros((B, blk.n_traj, n))
    status = np.zeros(B, dtype=np.int64)
    proj = np.zeros((B, n_steps, m))
    stop = np.zeros(B, dtype=np.int64)
    integrate_many(
        Stepper(n_steps, config.dt, *blk.coefs),
        Pattern(system.indptr, system.indices, system.Lp, system.Lj, system.sdx, system.sdz, system.sX, system.sZ),
        Model(
            blk.p_sub,
            config.p_sup,
            blk.sep,
            blk.x_mid,
            CLOSED_TOL,
            config.closure_gap_mm * 1e-3,
            flow_code(config),
            BLOWUP,
        ),
        Coupling(blk.sub_coef, flow_coefficient(config), config.contact == "layer", blk.kc, blk.cc),
        Stop(*stop_settings(config)),
        Matrices(blk.kv, blk.mv, blk.dv, blk.Lx, blk.G),
        State(blk.u, v, a),
        Outputs(width, gsep, lam, proj, p_in, blk.traj_every, tu, tv, stop),
        status,
    )
    return assemble_block(blk, ps, configs, status, width, gsep, lam, tu, p_in, proj, stop, t_wall)


def simulate_group_cuda(
    ps: list[Params], configs: list[SimConfig], max_batch: int | None = None, timings: dict | None = None
) -> list[SimResult]:
    """SimResults of rows that share a :func:`block_key`, integrated on the GPU (:mod:`vfcore.gpu`).

    The rows are set up on the CPU (:func:`prepare_block`), integrated in launches of at most ``max_batch``
    samples (default: what the GPU's free memory and the host's memory hold, :func:`vfcore.gpu.max_launch`)
    and assembled as on the CPU (:func:`assemble_block`). ``timings`` (a dict, optional) gets the seconds of
    each phase added: setup_s, to_device_s, kernel_s, to_host_s, assemble_s.
    """
    from .gpu import integrate_cuda, max_launch

    t_wall = time.perf_counter()
    blk = prepare_block(ps, configs)
    if timings is not None:
        timings["setup_s"] = timings.get("setup_s", 0.0) + time.perf_counter() - t_wall
    cap = max_launch(blk.system, blk.n_steps, blk.sub_coef.shape[1], blk.n_traj, blk.config.contact != "layer")
    if max_batch is not None:
        cap = max(1, min(cap, int(max_batch)))
    out: list[SimResult] = []
    for lo in range(0, len(ps), cap):
        sel = np.arange(lo, min(len(ps), lo + cap))
        status, width, gsep, lam, proj, p_in, tu, stop = integrate_cuda(blk, sel, timings)
        ta = time.perf_counter()
        out.extend(
            assemble_block(
                blk,
                [ps[i] for i in sel],
                [configs[i] for i in sel],
                status,
                width,
                gsep,
                lam,
                tu,
                p_in,
                proj,
                stop,
                t_wall,
            )
        )
        if timings is not None:
            timings["assemble_s"] = timings.get("assemble_s", 0.0) + time.perf_counter() - ta
    return out


def simulate_many(
    params_array, config: SimConfig | None = None, block: int = LOCKSTEP_WIDTH, configs=None, device: str = "cpu"
) -> list[SimResult]:
    """Simulate each row of ``params_array`` ((N, 7), ``PARAM_NAMES`` order, paper units).

    Rows are advanced ``block`` at a time in lock-step; results equal ``simulate`` row by
    row (a sample that blows up gets ``ok=False`` without stopping its block). A block of fewer
    than :data:`MIN_LOCKSTEP` rows (a single row, a group's last few) runs through the
    scalar kernel, which is faster there and gives the same bits.

    ``configs`` (optional, one SimConfig per row) overrides ``config`` row by row. Rows are
    grouped by :func:`block_key` (everything but the extensions in ``PER_SAMPLE_FIELDS``) and each
    group is simulated in blocks; the results come back in row order.

    ``device``: ``"cpu"`` (this lock-step kernel), ``"cuda"`` (one GPU thread per row, :mod:`vfcore.gpu`; each
    group goes to the GPU whole, in launches as large as its memory holds, and ``block`` is not used; raises
    :class:`vfcore.gpu.CudaUnavailable` where no GPU can run it) or ``"auto"`` (``"cuda"`` when a GPU is usable).
    """
    arr = _as_rows(params_array)
    if block < 1:
        raise ValueError(f"block must be >= 1, got {block}")
    from .gpu import resolve_device

    device = resolve_device(device)
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
        if device == "cuda":
            for i, r in zip(idx, simulate_group_cuda([ps[i] for i in idx], [configs[i] for i in idx])):
                out[i] = r
            continue
        for s in range(0, len(idx), block):
            sel = idx[s : s + block]
            if len(sel) < MIN_LOCKSTEP:
                res = [simulate_one(ps[i], configs[i]) for i in sel]
            else:
                res = _simulate_block([ps[i] for i in sel], [configs[i] for i in sel])
            for i, r in zip(sel, res):
                out[i] = r
    return out  # type: ignore[return-value]


def probe_seconds_per_sim(params_array, config: SimConfig, seconds: float = 0.1) -> float:
    """One core's seconds per simulation of ``config`` on this machine: the rows of ``params_array``
    simulated for ``seconds`` of model time in one lock-step block (no early stop), scaled to
    ``config.duration``. Give it as many rows as a fit's block (32): a simulation's first 50 ms
    cost more per model second than the rest and a narrow block costs more per row: 8 rows for
    0.05 s overestimated whole runs 2.3-2.6 times, 32 rows for 0.1 s 1.15-1.38 times (``benchmarks/bench_probe.py``, docs/inference.md "Cost
    before a run")."""
    arr = _as_rows(params_array)
    n = len(arr)
    if n == 0:
        raise ValueError("probe_seconds_per_sim needs at least one row")
    if seconds <= 0:
        raise ValueError(f"seconds must be > 0, got {seconds!r}")
    cfg = config.replace(duration=min(seconds, config.duration), discard=0.0, early_stop=False)
    simulate_many(arr[:1], cfg.replace(duration=cfg.dt * 4), block=1)  # load the compiled kernels
    t = time.perf_counter()
    simulate_many(arr, cfg, block=n)
    return (time.perf_counter() - t) / n * config.duration / cfg.duration
