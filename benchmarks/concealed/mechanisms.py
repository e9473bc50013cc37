"""Mechanisms of the concealed effects and of the camera (benchmarks/concealed/README.md).

Richer than the fitted extensions of ``vfcore/diagnose/extensions.py`` on purpose: a posterior
chink that varies along the fold length, a nonlinear anterior-posterior phase lag with an end
taper, two folds of different layer balance entrained 1:1, a non-uniform epithelium, a
quarter-wave subglottal tube, exposure averaging, a time stretch, and a scale error quantised to
pixels. Pure functions of simulated waveforms; the random draws are in ``generate.py``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from vfcore import SimConfig
from vfcore.result import HR_OVERSAMPLE

from .config import BASE_CONFIG, N_Y

__all__ = [
    "SUB_C",
    "PIXEL_MM",
    "frame_times",
    "sample_hr",
    "hr_times",
    "boxcar_average",
    "leak_area",
    "gap_profile",
    "zipper_area",
    "asymmetric_area",
    "epithelium_profile",
    "subglottal_modes",
    "quantise_scale",
    "forward_extensions_available",
]

SUB_C = 350.0  # m/s, speed of sound (warm humid air)
PIXEL_MM = 0.02  # width quantisation step


# ------------------------------------------------------------------ sampling helpers
def hr_times(res) -> np.ndarray:
    """Times (s, from the start of the kept window) of ``res.gaw_hr``."""
    return np.arange(np.asarray(res.gaw_hr).size) / (res.fps * HR_OVERSAMPLE)


def frame_times(n_obs: int, offset_frames: float, fps: float, rate_ratio: float = 1.0) -> np.ndarray:
    """Camera instants: frame k at ``(offset + k / rate_ratio) / fps`` (true rate = ratio * fps)."""
    return (float(offset_frames) + np.arange(n_obs) / float(rate_ratio)) / float(fps)


def sample_hr(y_hr: np.ndarray, t_hr: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Linear interpolation of a high-rate signal at ``t``; ``t`` must lie inside ``t_hr``."""
    t = np.asarray(t, dtype=float)
    if t.min() < t_hr[0] - 1e-12 or t.max() > t_hr[-1] + 1e-12:
        raise ValueError(
            f"sample times [{t.min():.4f}, {t.max():.4f}] s outside the simulated "
            f"window [{t_hr[0]:.4f}, {t_hr[-1]:.4f}] s"
        )
    return np.interp(t, t_hr, y_hr)


def _cumint(y_hr, t_hr, t):
    """Exact integral from t_hr[0] to t of the piecewise-linear interpolant of y_hr."""
    h = t_hr[1] - t_hr[0]
    c = np.concatenate([[0.0], np.cumsum(0.5 * h * (y_hr[1:] + y_hr[:-1]))])
    j = np.clip(np.floor((t - t_hr[0]) / h).astype(int), 0, y_hr.size - 2)
    s = t - t_hr[j]
    return c[j] + y_hr[j] * s + (y_hr[j + 1] - y_hr[j]) * s * s / (2.0 * h)


def boxcar_average(y_hr, t_hr, t, tau) -> np.ndarray:
    """Mean of the (piecewise-linear) signal over ``[t - tau/2, t + tau/2]`` per frame (exact)."""
    t = np.asarray(t, dtype=float)
    tau = np.broadcast_to(np.asarray(tau, dtype=float), t.shape)
    a, b = t - tau / 2, t + tau / 2
    if a.min() < t_hr[0] or b.max() > t_hr[-1]:
        raise ValueError("exposure window outside the simulated window")
    out = np.empty_like(t)
    pos = tau > 0
    out[pos] = (_cumint(y_hr, t_hr, b[pos]) - _cumint(y_hr, t_hr, a[pos])) / tau[pos]
    out[~pos] = np.interp(t[~pos], t_hr, y_hr)
    return out


def _slices(length_mm: float, n_y: int = N_Y):
    dy = length_mm / n_y
    return (np.arange(n_y) + 0.5) * dy, dy


# ------------------------------------------------------------------ leak
def gap_profile(
    chink_area_mm2: float, start_frac: float, length_mm: float, n_y: int = N_Y, power: float = 1.0
) -> np.ndarray:
    """Posterior chink: full gap width g(y), mm, on ``n_y`` slices (y = 0 anterior, L posterior):
    zero anterior of ``start_frac * L``, rising as ``s^power`` (s from 0 there to 1 at the posterior
    end; 1 = a linear wedge, < 1 a blunt gap, > 1 a narrow slit that opens at the end), scaled so
    that ``sum g dy = chink_area_mm2``."""
    y, dy = _slices(length_mm, n_y)
    shape = np.clip((y / length_mm - start_frac) / (1.0 - start_frac), 0.0, None) ** float(power)
    if chink_area_mm2 == 0 or shape.sum() == 0:
        return np.zeros(n_y)
    return shape * chink_area_mm2 / (shape.sum() * dy)


def leak_area(
    width_mm: np.ndarray, gap_mm: np.ndarray, env: np.ndarray | None = None, length_mm: float = BASE_CONFIG.length_mm
) -> np.ndarray:
    """Area of a glottis whose membranous width ``W(t) env(y)`` cannot close below the chink
    ``g(y)``: ``sum_y max(W(t) env(y), g(y)) dy`` (mm^2)."""
    gap_mm = np.asarray(gap_mm, dtype=float)
    n_y = gap_mm.size
    env = np.ones(n_y) if env is None else np.asarray(env, dtype=float)
    dy = length_mm / n_y
    w = np.asarray(width_mm, dtype=float)
    return np.maximum(w[..., None] * env, gap_mm).sum(axis=-1) * dy


# ------------------------------------------------------------------ zipper
def zipper_area(
    width_hr: np.ndarray,
    t_hr: np.ndarray,
    t_eval: np.ndarray,
    lag_s: float,
    power: float,
    env_q: float,
    length_mm: float = BASE_CONFIG.length_mm,
    n_y: int = N_Y,
    normalise: bool = True,
) -> np.ndarray:
    """A-P stack: ``width(y, t) = env(y) W(t - tau(y))`` with ``tau(y) = lag_s (y/L)^power`` and
    ``env(y) = sin(pi y/L)^env_q`` (normalised to mean 1 when ``normalise``; env_q = 0 -> 1);
    area ``sum_y max(width, 0) dy`` at the times ``t_eval``."""
    y, dy = _slices(length_mm, n_y)
    tau = lag_s * (y / length_mm) ** power
    env = np.sin(np.pi * y / length_mm) ** env_q
    if normalise:
        env = env / env.mean()
    tt = np.asarray(t_eval, dtype=float)[:, None] - tau[None, :]
    w = sample_hr(width_hr, t_hr, tt.ravel()).reshape(tt.shape)
    return np.maximum(w * env, 0.0).sum(axis=1) * dy


# ------------------------------------------------------------------ asymmetry
def _anchor(res, t_ref):
    """Cycle start (s) of ``res`` nearest ``t_ref``."""
    ts = np.asarray(res.cycles.t_start) if res.cycles is not None else np.empty(0)
    if ts.size == 0:
        raise ValueError("no cycles to anchor the entrainment")
    return float(ts[np.argmin(np.abs(ts - t_ref))])


def asymmetric_area(left, right, t_eval: np.ndarray, lag_cycles: float, t_centre: float) -> np.ndarray:
    """Glottal area of a left fold (SimResult ``left``) and a right fold (``right``, simulated with
    scaled stiffness) each contributing half its symmetric glottal width. The right fold is
    entrained 1:1 to the left fold's f0 by a linear time warp anchored at cycle starts near
    ``t_centre`` and lags it by ``lag_cycles`` of the left cycle:
    ``t_R = tR0 + (t - tL0 - lag/f0_L) f0_L/f0_R``, so one left period ``1/f0_L`` spans one right
    period ``1/f0_R``; width ``max(W_L/2 + W_R(t_R)/2, 0)``.

    (With the ratio inverted, ``f0_R/f0_L``, the right fold would run at ``f0_R^2/f0_L``, a
    two-frequency beating waveform rather than an entrained pair, which the fitted two-fold model
    cannot approach even at the true right fold. ``test_asymmetry_is_entrained`` checks the
    combined f0.)"""
    L = left.config.length_mm
    t_hr = hr_times(left)
    wl = sample_hr(np.asarray(left.gaw_hr) / L, t_hr, t_eval)
    if right is left:
        f_l = f_r = left.f0
    else:
        f_l, f_r = left.f0, right.f0
    ratio = f_l / f_r
    tl0 = _anchor(left, t_centre)
    tr0 = tl0 if right is left else _anchor(right, t_centre)
    t_r = tr0 + (np.asarray(t_eval) - tl0 - lag_cycles / f_l) * ratio
    wr = sample_hr(np.asarray(right.gaw_hr) / right.config.length_mm, hr_times(right), t_r)
    return np.maximum(0.5 * wl + 0.5 * wr, 0.0) * L


# ------------------------------------------------------------------ forward-model extensions
def forward_extensions_available() -> dict[str, bool]:
    """Whether this vfcore's SimConfig has the epithelium / subglottal fields (the forward-model extensions)."""
    names = {f.name for f in dataclasses.fields(SimConfig)}
    return {
        "epithelium": {"epithelium_E_kpa", "epithelium_h_mm", "epithelium_profile"} <= names,
        "subglottal": "subglottal_modes" in names,
    }


def epithelium_profile(medial_ratio: float, width_mm: float, mesh: str = BASE_CONFIG.mesh) -> tuple:
    """Per free-surface edge stiffness multipliers, 1 on the inferior/superior surfaces rising to
    ``medial_ratio`` on the medial surface (Gaussian in arc length about the most medial node)."""
    from vfcore.mesh import load_mesh

    m = load_mesh(mesh)
    p = np.asarray(m.points)[np.asarray(m.surface)] * 1e3  # mm, (x, z)
    seg = np.hypot(*np.diff(p, axis=0).T)
    s_node = np.concatenate([[0.0], np.cumsum(seg)])
    s_mid = 0.5 * (s_node[1:] + s_node[:-1])
    s_med = s_node[int(np.argmax(p[:, 0]))]
    prof = 1.0 + (medial_ratio - 1.0) * np.exp(-(((s_mid - s_med) / width_mm) ** 2))
    return tuple(float(x) for x in prof)


def subglottal_modes(tube_m: float, z1: float, zeta1: float, n_modes: int = 3, c: float = SUB_C) -> tuple:
    """Modes of a uniform tube closed at the lung end and open at the glottis (quarter-wave):
    ``f_k = (2k-1) c / (4 L)``, ``Z_k = Z1 / (2k-1)``, ``zeta_k = zeta1 (1 + 0.5 (k-1))``."""
    return tuple(
        ((2 * k - 1) * c / (4.0 * tube_m), min(1.0, zeta1 * (1 + 0.5 * (k - 1))), z1 / (2 * k - 1))
        for k in range(1, n_modes + 1)
    )


# ------------------------------------------------------------------ camera
def quantise_scale(
    area_mm2: np.ndarray, scale: float, length_mm: float = BASE_CONFIG.length_mm, pixel_mm: float = PIXEL_MM
) -> np.ndarray:
    """Scale error ``s`` on the area, then the width (area / L) quantised to ``pixel_mm``."""
    w = scale * np.asarray(area_mm2, dtype=float) / length_mm
    if pixel_mm > 0:
        w = np.round(w / pixel_mm) * pixel_mm
    return w * length_mm
