"""Synthetic high-speed videos rendered from a known glottal area waveform.

A generator only (no segmentation code here): it draws a dark glottal opening of a
prescribed area between two textured bright folds, then applies uneven
illumination, Gaussian blur and sensor noise, and quantises to 8 bits. The
opening's per-pixel coverage is computed analytically row by row, so the dark
fraction of each frame sums exactly to the prescribed area (before blur/noise).
Used by the tests in ``tests/vfvideo``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

__all__ = ["SyntheticVideo", "pulse_gaw", "render_video"]


def pulse_gaw(
    fps: float,
    f0: float,
    n_frames: int,
    peak_mm2: float = 8.0,
    open_quotient: float = 0.7,
    speed_quotient: float = 2.0,
    gap_mm2: float = 0.0,
    phase: float = 0.13,
) -> tuple[np.ndarray, np.ndarray]:
    """A known GAW: periodic asymmetric raised-cosine pulses with a closed phase.

    Parameters
    ----------
    fps, f0 : float
        Frame rate and fundamental frequency (Hz).
    n_frames : int
        Number of samples.
    peak_mm2 : float
        Peak area above the gap (mm^2).
    open_quotient, speed_quotient : float
        Fraction of the period that is open; opening/closing time ratio.
    gap_mm2 : float
        Constant posterior gap (mm^2) added to every frame.
    phase : float
        Start phase in cycles.

    Returns
    -------
    (t, area) : (ndarray, ndarray)
        Times in s and area in mm^2.
    """
    t = np.arange(n_frames) / fps
    ph = np.mod(f0 * t + phase, 1.0)
    t_op = open_quotient * speed_quotient / (1 + speed_quotient)
    t_cl = open_quotient - t_op
    a = np.zeros_like(ph)
    rising = ph < t_op
    a[rising] = 0.5 * (1 - np.cos(np.pi * ph[rising] / t_op))
    falling = (ph >= t_op) & (ph < open_quotient)
    a[falling] = 0.5 * (1 + np.cos(np.pi * (ph[falling] - t_op) / t_cl))
    return t, gap_mm2 + peak_mm2 * a


@dataclass
class SyntheticVideo:
    """Rendered frames and their ground truth.

    Attributes
    ----------
    frames : ndarray, uint8, shape (n, h, w)
    area_mm2 : ndarray (n,)
        Exact rendered opening area.
    area_left_mm2, area_right_mm2 : ndarray (n,)
        Parts of the area left and right of the glottal axis.
    fps, px_per_mm : float
    center : (row, col)
        Centre of the glottis in pixels.
    """

    frames: np.ndarray
    area_mm2: np.ndarray
    area_left_mm2: np.ndarray
    area_right_mm2: np.ndarray
    fps: float
    px_per_mm: float
    center: tuple[float, float]


def _smooth_noise(rng, shape, sigma):
    f = ndimage.gaussian_filter(rng.standard_normal(shape), sigma)
    return f / (f.std() + 1e-12)


def render_video(
    area_mm2: np.ndarray,
    fps: float,
    px_per_mm: float = 24.4,
    shape=(484, 504),
    center=(200.0, 300.0),
    length_mm: float = 12.0,
    tilt: float = 0.15,
    asymmetry: float = 0.0,
    blur_sigma: float = 1.2,
    noise_sigma: float = 4.0,
    illumination: float = 0.5,
    texture: float = 0.12,
    chink_mm2: float = 0.0,
    seed: int = 0,
) -> SyntheticVideo:
    """Render a grey-scale high-speed video of a glottis opening with the given areas.

    Parameters
    ----------
    area_mm2 : array_like (n,)
        Opening area per frame (mm^2).
    fps : float
        Frame rate (only stored).
    px_per_mm : float
        Spatial calibration (pixels per mm); the paper's camera: 24.4.
    shape : (h, w)
        Frame size in pixels (paper: 484 x 504).
    center : (row, col)
        Glottis centre (pixels), off-centre by default.
    length_mm : float
        Glottal length (anterior-posterior extent).
    tilt : float
        Horizontal shift of the glottal axis per row (dimensionless slope).
    asymmetry : float
        Left fold amplitude ``1 + asymmetry``, right ``1 - asymmetry``.
    blur_sigma : float
        Gaussian optical blur (pixels).
    noise_sigma : float
        Additive Gaussian noise, grey levels of 0..255.
    illumination : float
        Strength of the uneven illumination (0 = uniform): a vignette plus a linear
        gradient, multiplicative.
    texture : float
        Relative amplitude of the folds' smooth random texture.
    chink_mm2 : float
        Part of every frame's area drawn as a posterior glottal chink (a triangular
        opening over the last 30 % of the length that never closes); must not
        exceed the smallest area.
    seed : int
        Random seed.
    """
    area = np.asarray(area_mm2, dtype=float)
    if area.ndim != 1 or np.any(area < 0):
        raise ValueError("area_mm2 must be a 1D array of non-negative areas")
    rng = np.random.default_rng(seed)
    (h, w), n = shape, area.size
    L = int(round(length_mm * px_per_mm))
    r0 = int(round(center[0] - L / 2))
    if r0 < 2 or r0 + L > h - 2:
        raise ValueError("glottis does not fit into the frame")
    rows = r0 + np.arange(L)
    s = np.sin(np.pi * (np.arange(L) + 0.5) / L) ** 0.6  # opening profile along the glottis
    xc = center[1] + tilt * (rows + 0.5 - center[0])  # glottal axis (continuous column coords)
    px_area = 1.0 / px_per_mm**2
    if chink_mm2 > area.min() + 1e-12:
        raise ValueError("chink_mm2 exceeds the smallest area")
    g = np.clip((np.arange(L) + 0.5 - 0.7 * L) / (0.3 * L), 0.0, None)  # posterior chink profile
    G = chink_mm2 / px_area / (2.0 * g.sum())
    W = (area - chink_mm2) / px_area / (2.0 * s.sum())  # half-width scale per frame (px)
    kl, kr = 1.0 + asymmetry, 1.0 - asymmetry

    tissue, dark, illum = _background(rng, shape, texture, illumination)
    c_lo, c_hi = _column_window(xc, W.max() * max(kl, kr) + G * g.max() + 3, w)
    cols = np.arange(c_lo, c_hi, dtype=float)[None, :]

    frames = np.empty((n, h, w), dtype=np.uint8)
    left, right = np.empty(n), np.empty(n)
    for i in range(n):
        hl = kl * W[i] * s + G * g
        hr = kr * W[i] * s + G * g
        a_edge = (xc - hl)[:, None]
        b_edge = (xc + hr)[:, None]
        cov = np.clip(np.minimum(b_edge, cols + 1) - np.maximum(a_edge, cols), 0.0, 1.0)
        img = tissue.copy()
        sub = img[r0 : r0 + L, c_lo:c_hi]
        img[r0 : r0 + L, c_lo:c_hi] = sub * (1 - cov) + dark[r0 : r0 + L, c_lo:c_hi] * cov
        frames[i] = _expose(img, illum, blur_sigma, noise_sigma, rng)
        left[i] = hl.sum() * px_area
        right[i] = hr.sum() * px_area
    return SyntheticVideo(
        frames=frames,
        area_mm2=left + right,
        area_left_mm2=left,
        area_right_mm2=right,
        fps=float(fps),
        px_per_mm=float(px_per_mm),
        center=(float(center[0]), float(center[1])),
    )


def _background(
    rng: np.random.Generator, shape, texture: float, illumination: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The tissue's and the glottis' brightness (0..1) and the multiplicative illumination, each (h, w)."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    tissue = (
        0.78 * (1 + texture * _smooth_noise(rng, shape, 3.0)) * (1 + 0.5 * texture * _smooth_noise(rng, shape, 12.0))
    )
    dark = 0.08 * (1 + 0.3 * _smooth_noise(rng, shape, 4.0))
    cy, cx = h * 0.45, w * 0.55
    illum = (1 - illumination) + illumination * np.exp(
        -((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * (0.45 * max(h, w)) ** 2)
    )
    illum = illum * (1 + 0.3 * illumination * (xx / w - 0.5))
    return tissue, dark, illum


def _column_window(xc: np.ndarray, half_max: float, w: int) -> tuple[int, int]:
    """Columns ``[c_lo, c_hi)`` that hold the glottis at its widest (``half_max`` px either side of the axis
    ``xc``); ValueError when that reaches the frame's edge."""
    c_lo = max(0, int(np.floor(xc.min() - half_max)))
    c_hi = min(w, int(np.ceil(xc.max() + half_max)) + 1)
    if c_lo == 0 or c_hi == w:
        raise ValueError("glottis does not fit into the frame")
    return c_lo, c_hi


def _expose(
    img: np.ndarray, illum: np.ndarray, blur_sigma: float, noise_sigma: float, rng: np.random.Generator
) -> np.ndarray:
    """The camera's view of the scene ``img`` (h, w; 0..1, changed in place): illumination, optical blur,
    sensor noise, 8-bit grey levels."""
    img *= illum
    if blur_sigma > 0:
        img = ndimage.gaussian_filter(img, blur_sigma)
    img = img * 255.0 + rng.normal(0.0, noise_sigma, size=img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)
