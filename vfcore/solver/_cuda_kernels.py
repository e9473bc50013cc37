"""The lock-step ensemble as a numba.cuda kernel: one GPU thread per simulation.

Thread ``s`` of the launch runs the scalar time loop :func:`._kernels.integrate_ws` on sample ``s``'s
column of every per-sample array. Nothing of the physics lives here: ``integrate_ws`` and what it calls
(:func:`._kernels.surface_loads`, ``chol_solve``, ``contact_correct_ws``, ``contact_layer_ws``,
``projection_impulse``, ``subglottal_step``) are ``@njit`` functions that numba's CUDA target compiles as
device functions, so the GPU integrates the same equations, operation for operation, as
:func:`._kernels.integrate_coupled` (and so as the CPU lock-step kernel, which equals it bit for bit).

Layout (s = sample, innermost, so a warp's 32 threads read 32 neighbouring doubles of one entry):
  shared by all samples   indptr, indices (CSR pattern), Lp, Lj (factor pattern), sdx, sdz, sX, sZ
  kdm (3, nnz, B)         CSR values of K, M, D
  Lx (nnz_L, B)           Cholesky factor values of K_eff
  G (n, m, B)             contact columns K_eff^-1 e_j
  uva (3, n, B)           state u, v, a (advanced in place)
  spar (3, B)             p_sub, sep_ratio, x_mid
  sub_coef (n_modes, 3, B), kcc (2, m, B) (layer spring, dashpot)
  work: wn (4, n, B), wm (10, m, B), active (m, B), idx (m, B), S (m, m, B), subw (2, n_modes, B)
  out: width, gsep (n_steps, B); lam_out, proj_out (n_steps, m, B) (proj (0, m, B) = not recorded);
       p_in_out (n_steps, B) or (0, B); traj_u, traj_v (n_traj, n, B); status, stop_out (B,)

Floating point: the kernels use no fast-math, and :func:`launch` compiles with NVVM's FMA contraction
off (``fma=0``; numba exposes no switch for it, see :func:`_no_fma_contraction`), so each product and sum
is rounded as on the CPU and the GPU reproduces the CPU kernels' bits (docs/gpu.md).
"""

from __future__ import annotations

import contextlib
import threading

import numpy as np
from numba import cuda, njit
from numba.core import config as _numba_config

from ._args import Coupling, Matrices, Model, Outputs, Pattern, State, Stepper, Stop, Work
from ._kernels import integrate_ws

#: numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``, read when numba is first imported) runs kernels as
#: Python threads on the CPU.
SIMULATOR = bool(_numba_config.ENABLE_CUDASIM)
#: Threads per block: one warp pair. The thread's working set is in global memory (interleaved), so
#: occupancy is bounded by registers, not shared memory.
THREADS_PER_BLOCK = 64
#: Rows of the work arrays ``wn`` (n-vectors) and ``wm`` (m-vectors).
N_WORK_N = 4
N_WORK_M = 10


@njit(cache=True)
def run_sample(
    s,
    n_steps,
    h,
    am,
    af,
    beta,
    gamma,
    p_sup,
    closed_tol,
    g_reg,
    flow,
    blowup,
    flow_coef,
    layer,
    traj_every,
    stop_window,
    stop_width,
    stop_vel,
    indptr,
    indices,
    Lp,
    Lj,
    sdx,
    sdz,
    sX,
    sZ,
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
    lam_out,
    proj_out,
    p_in_out,
    traj_u,
    traj_v,
    status,
    stop_out,
):
    """Integrate sample ``s`` (a column of the interleaved arrays; see the module docstring) and write its
    status (0, the step it diverged at, or minus the step its contact did not settle at).

    The launch takes flat arrays and scalars; the argument groups of :mod:`._args` that ``integrate_ws`` takes
    are built here, in device code, from the sample's columns."""
    status[s] = integrate_ws(
        Stepper(n_steps, h, am, af, beta, gamma),
        Pattern(indptr, indices, Lp, Lj, sdx, sdz, sX, sZ),
        Model(spar[0, s], p_sup, spar[1, s], spar[2, s], closed_tol, g_reg, flow, blowup),
        Coupling(sub_coef[:, :, s], flow_coef, layer, kcc[0, :, s], kcc[1, :, s]),
        Stop(stop_window, stop_width, stop_vel),
        Matrices(kdm[0, :, s], kdm[1, :, s], kdm[2, :, s], Lx[:, s], G[:, :, s]),
        State(uva[0, :, s], uva[1, :, s], uva[2, :, s]),
        Outputs(
            width[:, s],
            gsep[:, s],
            lam_out[:, :, s],
            proj_out[:, :, s],
            p_in_out[:, s],
            traj_every,
            traj_u[:, :, s],
            traj_v[:, :, s],
            stop_out[s : s + 1],
        ),
        Work(
            wn[0, :, s],
            wn[1, :, s],
            wn[2, :, s],
            wn[3, :, s],
            wm[0, :, s],
            wm[1, :, s],
            wm[2, :, s],
            wm[3, :, s],
            wm[4, :, s],
            wm[5, :, s],
            wm[6, :, s],
            active[:, s],
            S[:, :, s],
            wm[7, :, s],
            idx[:, s],
            wm[8, :, s],
            wm[9, :, s],
            subw[0, :, s],
            subw[1, :, s],
        ),
    )


if SIMULATOR:
    # The simulator hands a kernel its arrays wrapped in its own Python objects, which an @njit function
    # cannot take; unwrapped, the thread runs the same compiled run_sample on the same NumPy memory.
    def _host_array(x):
        item = getattr(x, "_item", None)
        return item._ary if item is not None else x

    def _run(s, *args):
        run_sample(s, *[_host_array(x) for x in args])
else:
    _run = run_sample


@cuda.jit
def integrate_kernel(
    nb,
    n_steps,
    h,
    am,
    af,
    beta,
    gamma,
    p_sup,
    closed_tol,
    g_reg,
    flow,
    blowup,
    flow_coef,
    layer,
    traj_every,
    stop_window,
    stop_width,
    stop_vel,
    indptr,
    indices,
    Lp,
    Lj,
    sdx,
    sdz,
    sX,
    sZ,
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
    lam_out,
    proj_out,
    p_in_out,
    traj_u,
    traj_v,
    status,
    stop_out,
):
    """One thread per sample; threads past ``nb`` (the last block's padding) do nothing."""
    s = cuda.grid(1)
    if s < nb:
        _run(
            s,
            n_steps,
            h,
            am,
            af,
            beta,
            gamma,
            p_sup,
            closed_tol,
            g_reg,
            flow,
            blowup,
            flow_coef,
            layer,
            traj_every,
            stop_window,
            stop_width,
            stop_vel,
            indptr,
            indices,
            Lp,
            Lj,
            sdx,
            sdz,
            sX,
            sZ,
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
            lam_out,
            proj_out,
            p_in_out,
            traj_u,
            traj_v,
            status,
            stop_out,
        )


@cuda.jit
def fill_zero(x):
    """x[:] = 0 for a 1-D float64 device array, grid-stride."""
    i = cuda.grid(1)
    step = cuda.gridsize(1)
    while i < x.size:
        x[i] = 0.0
        i += step


_compile_lock = threading.Lock()


@contextlib.contextmanager
def _no_fma_contraction():
    """Compile with NVVM's ``-fma=0`` (no contraction of a multiply and an add into one rounding).

    numba passes NVVM only ``opt`` and, with fastmath, ``fma=1``; without fastmath NVVM's own default
    (contraction on) applies. The option is injected into numba's one call of NVVM for the module; where
    that call is not found (another numba-cuda layout) the kernel compiles with NVVM's default, and the GPU
    then agrees with the CPU to rounding instead of bit for bit.
    """
    try:
        from numba.cuda.cudadrv import nvvm

        orig = nvvm.compile_ir
    except (ImportError, AttributeError):
        yield False
        return

    def compile_ir(llvmir, **opts):
        opts.setdefault("fma", False)
        return orig(llvmir, **opts)

    nvvm.compile_ir = compile_ir
    try:
        yield True
    finally:
        nvvm.compile_ir = orig


def launch(nb, scalars, arrays, threads: int = THREADS_PER_BLOCK) -> None:
    """Run :func:`integrate_kernel` over ``nb`` samples: ``scalars`` (n_steps ... stop_vel) and ``arrays``
    (indptr ... stop_out, device arrays or NumPy arrays) in the kernel's order. Blocks until done."""
    tpb = max(1, min(threads, nb))
    grid = (nb + tpb - 1) // tpb
    if SIMULATOR:
        integrate_kernel[grid, tpb](nb, *scalars, *arrays)
        return
    with _compile_lock, _no_fma_contraction():
        # the first launch for these argument types compiles, inside the patch; later ones find it compiled
        integrate_kernel[grid, tpb](nb, *scalars, *arrays)
    cuda.synchronize()
