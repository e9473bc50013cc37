"""Argument groups of the time-integration kernels (:mod:`._kernels`, :mod:`._batch_kernels`,
:mod:`._cuda_kernels`).

Plain namedtuples of arrays and scalars: numba takes them in nopython and CUDA device code, and a kernel reads
a field by name instead of by its place among some fifty positional arguments. Shapes below are those of one
sample (the scalar kernel, a GPU thread's columns); the lock-step kernel's per-sample fields carry the sample
index first (see :func:`._batch_kernels.integrate_many`). n = solver dofs, m = free-surface nodes.
"""

from __future__ import annotations

from collections import namedtuple

#: The time grid and the generalised-alpha constants: n_steps (int), h (s), am, af, beta, gamma
#: (:func:`._kernels.newmark_coefficients`).
Stepper = namedtuple("Stepper", "n_steps h am af beta gamma")

#: Sparsity patterns and the free surface, shared by all samples: indptr (n + 1,), indices (nnz,) (CSR of
#: K, M, D); Lp (n + 1,), Lj (nnz_L,) (the Cholesky factor's pattern); sdx, sdz (m,) int64 (x and z dof of
#: each surface node, -1 = fixed); sX, sZ (m,) reference coordinates, m.
Pattern = namedtuple("Pattern", "indptr indices Lp Lj sdx sdz sX sZ")

#: The flow load and the run's guards: p_sub, p_sup (Pa), sep_ratio, x_mid (m, the midline), closed_tol (m),
#: g_reg (m, small-gap regularisation), flow (``FLOW_PAPER`` / ``FLOW_CONTINUOUS``), blowup (m).
Model = namedtuple("Model", "p_sub p_sup sep_ratio x_mid closed_tol g_reg flow blowup")

#: Model extensions: sub_coef (n_modes, 3) subglottal resonators (0 rows = off); flow_coef = 2 L sqrt(2 / rho_air)
#: (the glottal flow is Q = flow_coef * gsep * sqrt(p_in - p_sup), m^3/s); layer (bool: the compliant contact layer
#: instead of the rigid midline); kc (m,) N/m^2 and cc (m,) N s/m^2, the layer's spring and dashpot.
Coupling = namedtuple("Coupling", "sub_coef flow_coef layer kc cc")

#: Settled-response stop: window (steps, 0 = off), width (m), vel (m/s).
Stop = namedtuple("Stop", "window width vel")

#: Per-sample matrices: kval, mval, dval (nnz,) CSR values of K, M, D; Lx (nnz_L,) factor values of K_eff
#: (diagonal stored as its reciprocal); G (n, m) contact columns K_eff^-1 e_j.
Matrices = namedtuple("Matrices", "kval mval dval Lx G")

#: The state u, v, a (n,) (m, m/s, m/s^2), advanced in place.
State = namedtuple("State", "u v a")

#: Per-step outputs: width, gsep (n_steps,) m; lam (n_steps, m) N/m; proj (n_steps, m) N s/m, or (0, m) = not
#: recorded; p_in (n_steps,) Pa, or (0,) without resonators; traj_every (int, 0 = no trajectories), traj_u,
#: traj_v (n_traj, n); stop (1,) int64, the step the run settled at (0 = ran to the end).
Outputs = namedtuple("Outputs", "width gsep lam proj p_in traj_every traj_u traj_v stop")

#: Caller-owned work arrays of :func:`._kernels.integrate_ws`: y1, y2, r, u0 (n,); xs, zs, gap, fx, fz, pres,
#: lam (m,); active (m,) bool; S (m, m); rhs (m,); idx (m,) int64; keff, bb (m,); sub_p1, sub_p2 (n_modes,).
Work = namedtuple("Work", "y1 y2 r u0 xs zs gap fx fz pres lam active S rhs idx keff bb sub_p1 sub_p2")
