"""GPU ensemble backend of :func:`vfcore.batch.simulate_many` (``device="cuda"``).

The per-sample set-up (material values, medial prestress, factorisation, contact columns) stays on the CPU,
shared with the CPU lock-step path (:func:`vfcore.batch.prepare_block`); the time integration runs on the GPU,
one thread per simulation (:func:`integrate_cuda`, :mod:`vfcore.solver._cuda_kernels`); the per-step outputs
come back and :func:`vfcore.batch.assemble_block` turns them into the same :class:`SimResult` s as the CPU path
(:func:`vfcore.batch.simulate_group_cuda` strings the three together).
docs/gpu.md describes the design and what is measured.

Devices: ``"cpu"`` (the lock-step kernel), ``"cuda"`` (this module; an error naming what is missing when no
GPU can be used) and ``"auto"`` (``"cuda"`` when a real GPU is usable, else ``"cpu"``). ``NUMBA_ENABLE_CUDASIM=1``
(set before numba is imported) runs ``"cuda"`` on numba's CUDA simulator, on the CPU: how the kernel is
tested without a GPU.
"""

from __future__ import annotations

import os
import time

import numpy as np

DEVICES = ("cpu", "cuda", "auto")

#: Share of the free GPU memory, and of the host's memory, one launch may fill (inputs, work and outputs on
#: the GPU; the outputs again on the host while they are turned into results).
DEVICE_MEMORY_SHARE = 0.6
HOST_MEMORY_SHARE = 0.25


class CudaUnavailable(RuntimeError):
    """``device="cuda"`` was asked for where no GPU can run the kernel."""


def cuda_status() -> tuple[bool, str]:
    """(usable, what): whether the CUDA backend can run here, and the device, or the reason it cannot."""
    try:
        from numba import cuda
        from numba.core import config
    except Exception as exc:  # noqa: BLE001 - any import failure means: no CUDA backend
        return False, f"numba.cuda cannot be imported ({type(exc).__name__}: {exc})"
    if config.ENABLE_CUDASIM:
        return True, "numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1), on the CPU"
    try:
        if not cuda.is_available():
            why = " ".join(str(cuda.cuda_error() or "no CUDA device was found").split())
            return False, f"no usable NVIDIA GPU ({why})"
        from numba.cuda.cudadrv import nvvm

        if not nvvm.is_available():
            return False, (
                "the GPU's driver is present but the CUDA toolkit's NVVM compiler is not: install the "
                "[gpu] extra (numba-cuda with the CUDA 12 toolkit wheels) or set CUDA_HOME to a toolkit"
            )
        dev = cuda.get_current_device()
        name = dev.name.decode() if isinstance(dev.name, bytes) else str(dev.name)
        return True, f"{name} (compute capability {dev.compute_capability[0]}.{dev.compute_capability[1]})"
    except Exception as exc:  # noqa: BLE001 - a broken driver or toolkit reads as unavailable, with its reason
        return False, f"the CUDA driver failed to start ({type(exc).__name__}: {' '.join(str(exc).split())})"


def is_simulator() -> bool:
    from numba.core import config

    return bool(config.ENABLE_CUDASIM)


def resolve_device(device: str) -> str:
    """``"cpu"`` or ``"cuda"`` for ``device`` in :data:`DEVICES`; raises :class:`CudaUnavailable` (one line saying
    what is missing) for ``"cuda"`` without a usable GPU. ``"auto"`` never picks the simulator."""
    if device not in DEVICES:
        raise ValueError(f"device must be one of {DEVICES}, got {device!r}")
    if device == "cpu":
        return "cpu"
    ok, what = cuda_status()
    if device == "auto":
        return "cuda" if ok and not is_simulator() else "cpu"
    if not ok:
        raise CudaUnavailable(f"device='cuda' cannot run here: {what}; use device='cpu' (or 'auto')")
    return "cuda"


def _bytes_per_sample(system, n_steps: int, nmod: int, n_traj: int, projection: bool) -> int:
    n, m, nnz, nl = system.n, system.sdx.size, system.indices.size, system.nnz_factor
    doubles = (
        3 * nnz
        + nl
        + n * m
        + 3 * n
        + 3
        + 3 * nmod
        + 2 * m  # inputs
        + 4 * n
        + 10 * m
        + m
        + m * m
        + 2 * nmod  # work (idx int64 counted as a double)
        + 2 * n_steps
        + n_steps * m * (2 if projection else 1)  # outputs
        + (n_steps if nmod else 0)
        + 2 * n_traj * n
        + 2
    )
    return 8 * doubles + m  # + the bool active set


def _host_memory() -> int:
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 8 << 30


def max_launch(system, n_steps: int, nmod: int, n_traj: int, projection: bool, host: bool = True) -> int:
    """Most samples one launch holds: a share of the free GPU memory and (``host``: the outputs come back) of
    the host's memory."""
    from numba import cuda

    per = _bytes_per_sample(system, n_steps, nmod, n_traj, projection)
    cap = DEVICE_MEMORY_SHARE * cuda.current_context().get_memory_info()[0]
    if host:
        cap = min(cap, HOST_MEMORY_SHARE * _host_memory())
    return max(1, int(min(cap, 1 << 40) // per))


def _zeros(shape):
    """A zero-filled float64 device array (filled on the device, not copied from the host)."""
    from numba import cuda
    from .solver._cuda_kernels import SIMULATOR, THREADS_PER_BLOCK, fill_zero

    if SIMULATOR or int(np.prod(shape)) == 0:
        return cuda.to_device(np.zeros(shape))
    d = cuda.device_array(shape)
    fill_zero[256, THREADS_PER_BLOCK](d.reshape(int(np.prod(shape))))
    return d


def integrate_cuda(blk, sel: np.ndarray, timings: dict | None = None, fetch: bool = True):
    """Integrate the samples ``sel`` of a prepared block (:class:`vfcore.batch.BlockInputs`) on the GPU in one
    launch. Returns (status, width, gsep, lam, proj, p_in, traj_u, stop), each indexed ``[b]`` over ``sel`` and
    contiguous per sample, as :func:`vfcore.batch.assemble_block` takes them. ``sel`` may repeat a sample.
    ``timings`` (a dict, optional) gets the seconds of to_device_s, kernel_s (compilation on the first call
    included) and to_host_s added, and device_bytes (the most this module allocated for one launch).
    ``fetch=False`` leaves the outputs on the GPU and returns None (to time the integration alone)."""
    from numba import cuda

    from .simcore import BLOWUP, CLOSED_TOL, flow_code, flow_coefficient, stop_settings
    from .solver._cuda_kernels import N_WORK_M, N_WORK_N, launch

    t0 = time.perf_counter()
    config, system, n_steps = blk.config, blk.system, blk.n_steps
    B = sel.size
    n, m = system.n, system.sdx.size
    nmod = blk.sub_coef.shape[1]
    projection = config.contact != "layer"
    c = np.ascontiguousarray
    # interleaved [entry, sample] copies of the block's inputs
    kdm = cuda.to_device(c(np.stack([blk.kv[:, sel], blk.mv[:, sel], blk.dv[:, sel]])))
    Lx = cuda.to_device(c(blk.Lx[:, sel]))
    G = cuda.to_device(c(blk.G[sel].transpose(1, 2, 0)))
    uva = np.zeros((3, n, B))
    uva[0] = blk.u[:, sel]
    uva = cuda.to_device(uva)
    spar = cuda.to_device(c(np.stack([blk.p_sub[sel], blk.sep[sel], blk.x_mid[sel]])))
    sub_coef = cuda.to_device(c(blk.sub_coef[sel].transpose(1, 2, 0)))
    kcc = cuda.to_device(c(np.stack([blk.kc[sel].T, blk.cc[sel].T])))
    wn = cuda.device_array((N_WORK_N, n, B))
    wm = cuda.device_array((N_WORK_M, m, B))
    active = cuda.device_array((m, B), dtype=np.bool_)
    idx = cuda.device_array((m, B), dtype=np.int64)
    S = cuda.device_array((m, m, B))
    subw = cuda.device_array((2, nmod, B))
    width = cuda.device_array((n_steps, B))
    gsep = cuda.device_array((n_steps, B))
    lam = cuda.device_array((n_steps, m, B))
    proj = _zeros((n_steps if projection else 0, m, B))
    p_in = cuda.device_array((n_steps if nmod else 0, B))
    tu = cuda.device_array((blk.n_traj, n, B))
    tv = cuda.device_array((blk.n_traj, n, B))
    status = cuda.to_device(np.zeros(B, dtype=np.int64))
    stop = cuda.to_device(np.zeros(B, dtype=np.int64))
    shared = [
        cuda.to_device(x)
        for x in (system.indptr, system.indices, system.Lp, system.Lj, system.sdx, system.sdz, system.sX, system.sZ)
    ]
    t1 = time.perf_counter()
    stop_window, stop_width, stop_vel = stop_settings(config)
    f = float
    # fixed scalar types: one compiled kernel whatever numeric types a config holds
    scalars = (
        int(n_steps),
        f(config.dt),
        *(f(x) for x in blk.coefs),
        f(config.p_sup),
        f(CLOSED_TOL),
        f(config.closure_gap_mm * 1e-3),
        int(flow_code(config)),
        f(BLOWUP),
        f(flow_coefficient(config)),
        bool(not projection),
        int(blk.traj_every),
        int(stop_window),
        f(stop_width),
        f(stop_vel),
    )
    launch(
        B,
        scalars,
        (
            *shared,
            kdm,
            Lx,
            G,
            uva,
            spar,
            sub_coef,
            kcc,
            wn,
            wm,
            active,
            idx,
            S,
            subw,
            width,
            gsep,
            lam,
            proj,
            p_in,
            tu,
            tv,
            status,
            stop,
        ),
    )
    t2 = time.perf_counter()
    if timings is not None:
        timings["kernel_s"] = timings.get("kernel_s", 0.0) + t2 - t1
        timings["to_device_s"] = timings.get("to_device_s", 0.0) + t1 - t0
        used = sum(
            int(x.nbytes)
            for x in (
                *shared,
                kdm,
                Lx,
                G,
                uva,
                spar,
                sub_coef,
                kcc,
                wn,
                wm,
                active,
                idx,
                S,
                subw,
                width,
                gsep,
                lam,
                proj,
                p_in,
                tu,
                tv,
                status,
                stop,
            )
        )
        timings["device_bytes"] = max(timings.get("device_bytes", 0), used)
    if not fetch:
        return None
    h_width = width.copy_to_host().T
    h_gsep = gsep.copy_to_host().T
    h_lam = lam.copy_to_host().transpose(2, 0, 1)
    h_proj = proj.copy_to_host().transpose(2, 0, 1) if projection else np.zeros((B, n_steps, m))
    if nmod:
        h_p_in = p_in.copy_to_host().T
    else:
        h_p_in = np.zeros((B, 0))
    h_tu = tu.copy_to_host().transpose(2, 0, 1)
    out = (status.copy_to_host(), c(h_width), c(h_gsep), c(h_lam), c(h_proj), c(h_p_in), c(h_tu), stop.copy_to_host())
    t3 = time.perf_counter()
    if timings is not None:
        timings["to_host_s"] = timings.get("to_host_s", 0.0) + t3 - t2
    return out
