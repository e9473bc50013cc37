"""The per-simulation steps shared by the scalar (:mod:`vfcore.forward`) and the lock-step
(:mod:`vfcore.batch`) forward models: model constants, set-up (material values, medial prestress,
factorisation, contact law), and the assembly of a :class:`SimResult` from the per-step arrays.

Both time loops call exactly these functions, which is what keeps a lock-step row bit-identical to a
scalar simulation. Hadwin et al. (2019), Sections 3 and 4.1; :ref:`model`.
"""

from __future__ import annotations

import math
import time

import numpy as np

from .config import SimConfig
from .observe import downsample
from .params import Params
from .result import HR_OVERSAMPLE, CycleSummary, SimResult
from .solver import _kernels as kern
from .solver.system import System

RHO_AIR = 1.14  # kg/m^3 (Hadwin et al. 2019)
CLOSED_TOL = 1e-9  # m: a surface node within 1 nm of the midline closes the glottis (the paper's flow rule)


def flow_code(config: SimConfig) -> int:
    """The kernels' ``flow`` argument for ``config.flow`` (:data:`.solver._kernels.FLOW_PAPER` or
    ``FLOW_CONTINUOUS``)."""
    from .solver._kernels import FLOW_CONTINUOUS, FLOW_PAPER

    return FLOW_PAPER if config.flow == "paper" else FLOW_CONTINUOUS


MIN_CYCLE_AMPLITUDE = 0.05  # mm^2
BLOWUP = 1e-2  # m: a displacement beyond 1 cm (more than the 8.4-mm fold width) is a failure
# Settled-response stop (SimConfig.early_stop; :ref:`model-numerics-stopping-settled-simulations`): windows of
# 50 ms (longer than any period the model produces), quiet when the width moved by at most 10 nm
# (1.7e-4 mm^2 of area) and no node moved faster than 1 mm/s (a phonating fold: ~0.1-0.5 m/s), nor faster
# than in the window before.
STOP_WINDOW_S = 0.05
STOP_WIDTH = 1e-8  # m
STOP_VEL = 1e-3  # m/s


def stop_settings(config: SimConfig) -> tuple[int, float, float]:
    """(stop_window steps, stop_width m, stop_vel m/s) for the kernels; window 0 = off."""
    if not config.early_stop:
        return 0, 0.0, 0.0
    return max(1, int(round(STOP_WINDOW_S / config.dt))), STOP_WIDTH, STOP_VEL


def as_params(params) -> Params:
    """``params`` (Params, dict or array in ``PARAM_NAMES`` order, paper units) as Params."""
    if isinstance(params, Params):
        return params
    if isinstance(params, dict):
        return Params.from_dict(params)
    return Params.from_array(params)


def midline(p: Params, config: SimConfig) -> float:
    """Midline (contact plane) position in m: x0 plus the prephonatory half gap."""
    return (p.x0 + config.half_gap_mm) * 1e-3


def contact_law(p: Params, config: SimConfig, system: System) -> tuple[np.ndarray, np.ndarray]:
    """Per-node spring kc (N/m^2) and dashpot cc (N s/m^2) of the compliant contact layer.

    A layer of thickness h with the cover's modulus and viscosity, compressed by the overlap d of a
    node with the midline, pushes back with the pressure E_cover d / h + eta d' / h (uniaxial
    Kelvin-Voigt); the node carries it over its edge share. Both scale with the material parameters,
    so the model's exact common-scale symmetry (:ref:`inference`, "The common scale") is kept.
    Zeros for the rigid ``contact="projection"`` (then unused).
    """
    m = system.sdx.size
    if config.contact != "layer":
        return np.zeros(m), np.zeros(m)
    si = p.si()
    share = system.mesh.surface_weights()
    hl = config.contact_layer_mm * 1e-3
    return si["E_cover"] / hl * share, si["eta"] / hl * share


def prestress(
    system: System, K_vals: np.ndarray, x_mid: float, kc: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Static equilibrium with no surface node beyond the midline (medial compression).

    Solves K u = E lambda with the active-set contact of :func:`_kernels.contact_correct`, or, given
    the layer springs ``kc`` (m,), with the static compliant layer of :func:`_kernels.contact_layer_ws`.
    Returns (u (n,), contact force per surface node (m,), N/m >= 0).
    """
    u = np.zeros(system.n)
    m = system.sdx.size
    lam = np.zeros(m)
    if np.all(system.sX <= x_mid):
        return u, lam
    Lk = system.factor(K_vals)
    G = system.contact_columns(Lk)
    active = np.zeros(m, dtype=np.bool_)
    if kc is None:
        it = kern.contact_correct(u, system.sdx, system.sX, x_mid, G, lam, active, 200)
    else:
        it = kern.contact_layer_ws(
            u,
            np.zeros(system.n),
            1.0,
            1.0,
            system.sdx,
            system.sX,
            x_mid,
            G,
            kc,
            np.zeros(m),
            lam,
            active,
            200,
            np.empty(system.n),
            np.empty((m, m)),
            np.empty(m),
            np.empty(m, dtype=np.int64),
            np.empty(m),
            np.empty(m),
        )
    if it < 0:
        raise RuntimeError("static contact (medial compression) did not converge")
    return u, -lam


def cycle_summary(
    t: np.ndarray,
    gaw: np.ndarray,
    flow: np.ndarray,
    cp_max: np.ndarray,
    force: np.ndarray | None = None,
    share: np.ndarray | None = None,
    h: float = 0.0,
    proj: np.ndarray | None = None,
) -> CycleSummary:
    """Cycles between successive upward crossings of the mean area (opening phases).

    ``force`` (n, m) per-step contact forces, N/m, ``share`` (m,) edge share of each surface node, m,
    and ``h`` the step, s: the contact impulse, duration and pressure in contact of each cycle
    (see :class:`CycleSummary`); without them those arrays stay empty. ``proj`` (n, m), N s/m: the
    momentum the inelastic projection removes per step and node (added to the impulse).
    """
    empty = np.empty(0)
    level = 0.5 * (gaw.max() + gaw.min())
    # a flicker below 0.05 mm^2 (a few camera pixels) is no oscillation
    if gaw.max() - gaw.min() < MIN_CYCLE_AMPLITUDE:
        return CycleSummary(empty, empty, empty, empty, empty, empty, empty, empty, empty, empty)
    up = np.nonzero((gaw[:-1] < level) & (gaw[1:] >= level))[0]
    if up.size >= 2:
        # cycles shorter than 1/1000 s (above any phonation f0) are numerical chatter
        keep = np.concatenate([[True], np.diff(t[up]) > 1e-3])
        up = up[keep]
    if up.size < 2:
        return CycleSummary(empty, empty, empty, empty, empty, empty, empty, empty, empty, empty)
    # sub-sample crossing times
    frac = (level - gaw[up]) / (gaw[up + 1] - gaw[up])
    tc = t[up] + frac * (t[up + 1] - t[up])
    per, pk, mn, qf, cm, cx = [], [], [], [], [], []
    imp, dur, pin = [], [], []
    if force is not None:
        f_tot = force.sum(axis=1)  # N/m on the whole surface, per step
        p_tot = proj.sum(axis=1) if proj is not None else np.zeros(f_tot.size)  # N s/m, per step
        touching = force > 0.0
        c_len = touching.astype(float) @ share  # m of surface in contact, per step
    for a, b in zip(up[:-1], up[1:]):
        sl = slice(a + 1, b + 1)
        pk.append(gaw[sl].max())
        mn.append(gaw[sl].min())
        qf.append(flow[sl].mean())
        cm.append(cp_max[sl].mean())
        cx.append(cp_max[sl].max())
        if force is not None:
            i_c = h * f_tot[sl].sum() + p_tot[sl].sum()
            ext = h * c_len[sl].sum()
            imp.append(i_c)
            dur.append(h * np.count_nonzero(touching[sl].any(axis=1)))
            pin.append(i_c / ext if ext > 0.0 else 0.0)
    per = np.diff(tc)
    return CycleSummary(
        t_start=tc[:-1],
        period=per,
        peak_area=np.array(pk),
        min_area=np.array(mn),
        mean_flow=np.array(qf),
        mean_peak_contact_pressure_unconverged=np.array(cm),
        max_contact_pressure_unconverged=np.array(cx),
        contact_impulse=np.array(imp),
        contact_duration=np.array(dur),
        contact_pressure_in_contact=np.array(pin),
    )


def flow_coefficient(config: SimConfig) -> float:
    """Q = flow_coefficient * gsep * sqrt(p_in - p_sup) (m^3/s; gsep the half gap at separation, m):
    Q = 1.3 A_min sqrt(2 dp / rho_air) with A = 2 L g, as the time loops use it."""
    return 2.0 * (config.length_mm * 1e-3) * math.sqrt(2.0 / RHO_AIR)


def setup(p: Params, config: SimConfig, system: System):
    """Per-simulation set-up shared by :func:`vfcore.forward.simulate` and :mod:`vfcore.batch`.

    Returns (K_vals, D_vals, M_vals) CSR values on the system's pattern (epithelium membrane
    included when configured), the pre-stressed initial displacement u (n,), the Cholesky factor
    values Lx of K_eff = cK K + cD D + cM M and the contact columns G = K_eff^-1 E (n, m).
    """
    si = p.si()
    K_vals = system.stiffness_values((si["E_body"], si["E_lig"], si["E_cover"]))
    D_vals = si["eta"] * system.d_vals
    if config.has_epithelium:
        # membrane on the free surface: enters K (prestress, K_eff, contact columns G, the
        # K u product of the time loop) and D alike
        K_ep, D_ep = system.epithelium_values(
            config.epithelium_E_kpa, config.epithelium_h_mm, config.epithelium_profile, si["eta"]
        )
        K_vals = K_vals + K_ep
        D_vals = D_vals + D_ep
    M_vals = si["rho"] * system.m_vals
    kc, _ = contact_law(p, config, system)
    u, _ = prestress(system, K_vals, midline(p, config), kc if config.contact == "layer" else None)
    cM, cD, cK = kern.effective_scales(config.dt, config.rho_inf)
    Lx = system.factor(cK * K_vals + cD * D_vals + cM * M_vals)
    return K_vals, D_vals, M_vals, u, Lx, system.contact_columns(Lx)


def assemble_result(
    p: Params,
    config: SimConfig,
    system: System,
    status: int,
    width: np.ndarray,
    gsep: np.ndarray,
    lam: np.ndarray,
    traj_every: int,
    tu: np.ndarray,
    t_wall: float,
    p_in: np.ndarray | None = None,
    proj: np.ndarray | None = None,
    stop_step: int = 0,
) -> SimResult:
    """SimResult from the per-step arrays of one integration (status 0 = ok, else failing step).

    ``p_in`` (n_steps,): glottal inlet pressure after each step (subglottal coupling), or None
    (then it is ``p_sub`` throughout and ``SimResult.p_in`` stays empty). ``proj`` (n_steps, m): the
    projection impulses of the kernel (N s/m), or None (then the contact impulse is the multipliers' alone).
    ``stop_step``: the step at which a settled response stopped (0 = ran to the end).
    """
    si = p.si()
    h = config.dt
    n_steps = width.size
    n_traj = tu.shape[0]
    L = config.length_mm * 1e-3
    if status != 0:
        why = "state diverged" if status > 0 else "contact active set did not settle"
        return SimResult(
            ok=False,
            message=f"{why} at t = {abs(status) * h * 1e3:.2f} ms",
            params=p,
            config=config,
            fps=config.fps,
            wall_time=time.perf_counter() - t_wall,
        )
    dp = max(si["p_sub"] - config.p_sup, 0.0)
    t_all = h * np.arange(1, n_steps + 1)
    gaw_full = config.length_mm * width * 1e3  # mm * mm
    if p_in is None:
        flow_full = 2.0 * L * gsep * math.sqrt(2.0 * dp / RHO_AIR)  # m^3/s
    else:
        # exactly the flow that drove the resonators: step k uses p_in after step k - 1 (explicit coupling)
        p_prev = np.concatenate([[si["p_sub"]], p_in[:-1]])
        flow_full = 2.0 * L * gsep * np.sqrt(2.0 * np.maximum(p_prev - config.p_sup, 0.0) / RHO_AIR)
    w_share = system.mesh.surface_weights()
    cp_full = lam / np.where(w_share > 0, w_share, np.inf)  # Pa
    keep = t_all >= config.discard - 1e-12
    cyc = cycle_summary(
        t_all[keep] - config.discard,
        gaw_full[keep],
        flow_full[keep],
        cp_full[keep].max(axis=1),
        lam[keep],
        w_share,
        h,
        None if proj is None else proj[keep],
    )
    tc, gaw = downsample(t_all, gaw_full, config.fps, config.discard)
    _, gaw_hr = downsample(t_all, gaw_full, config.fps * HR_OVERSAMPLE, config.discard)
    gaw_hr = gaw_hr[: HR_OVERSAMPLE * (gaw.size - 1) + 1]
    _, wd = downsample(t_all, width * 1e3, config.fps, config.discard)
    _, q = downsample(t_all, flow_full, config.fps, config.discard)
    _, cp = downsample(t_all, cp_full, config.fps, config.discard)
    _, cf = downsample(t_all, lam, config.fps, config.discard)
    p_in_cam = np.empty(0)
    if p_in is not None:
        _, p_in_cam = downsample(t_all, p_in, config.fps, config.discard)
    traj = None
    if config.keep_trajectories:
        t_tr = h * traj_every * np.arange(1, n_traj + 1)
        full = np.zeros((n_traj, 2 * system.mesh.n_nodes))
        full[:, system.dofs] = tu
        _, tr = downsample(t_tr, full, config.fps, config.discard)
        traj = tr.reshape(tr.shape[0], -1, 2) * 1e3
    return SimResult(
        ok=True,
        message="ok",
        params=p,
        config=config,
        fps=config.fps,
        t=tc,
        gaw=gaw,
        width=wd,
        flow=q,
        contact_pressure=cp,
        contact_force=cf,
        surface_z=system.sZ * 1e3,
        cycles=cyc,
        trajectories=traj,
        wall_time=time.perf_counter() - t_wall,
        gaw_hr=gaw_hr,
        p_in=p_in_cam,
        settled_at=stop_step * h,
    )
