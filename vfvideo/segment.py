"""Glottis segmentation in high-speed video frames.

Steps (each documented in ``:ref:`video`):

1. Region of interest: the glottis is the part of the image that changes most over
   time. The temporal standard deviation, smoothed, is thresholded and its
   strongest connected component (the *motion core*) padded into a box. The box
   grows while the segmented opening touches its border.
2. Illumination: each ROI pixel is divided by its own bright (tissue) level, the
   90th temporal percentile, with pixels that are dark nearly all the time filled in
   by normalised convolution from their neighbours, and by a per-frame gain (flicker).
   The result ``r`` is ~1 on tissue and ~(dark/tissue) in the opening, independent
   of uneven illumination.
3. Threshold: halfway between the dark level (median of the clearly dark pixels of
   the motion core) and the tissue level (median of ``r``): for a symmetric blur this places the
   edge where the pixel is half covered, so the pixel count is unbiased.
4. Region growing with temporal consistency: dark pixels are labelled in 3D
   (rows, columns and time, face connectivity); a space-time region is kept only if
   it contains a strongly dark seed (a quarter of the way from dark to tissue)
   inside the motion core. Narrow openings near closure, which never reach the seed
   level, are kept through their connection in time with open frames; isolated dark
   blobs (noise, static dark structures) are dropped. Holes (specular highlights)
   are filled per frame.
5. Quality per frame: the opening touches the ROI border, an area jump (more than
   20 % of the peak area and 5 robust s.d. away from the mean of the two neighbours), or an exposure change of more than 30 %.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from .io import VideoError

__all__ = ["Segmentation", "find_roi", "segment_frames"]


@dataclass
class Segmentation:
    """Result of :func:`segment_frames` (pixel units; absolute frame coordinates).

    Attributes
    ----------
    masks : bool ndarray (n, roi_h, roi_w)
        Opening per frame, inside the ROI.
    roi : (r0, r1, c0, c1)
        Rows r0:r1 and columns c0:c1 of the frame.
    area_px : ndarray (n,)
        Pixel count per frame.
    ok : bool ndarray (n,)
        Per-frame quality flag.
    flags : list of str
        Reasons for each frame ('' when fine; comma-separated).
    left_edge, right_edge : ndarray (n, roi_h)
        Left and right edge of the opening in each ROI row (column coordinate of the
        pixel boundary, absolute), NaN where the row is closed.
    axis : (a, b)
        Glottal main axis, column = a + b * row (continuous pixel coordinates).
    left_px, right_px : ndarray (n,)
        Parts of the area left / right of the axis (pixels).
    threshold, dark_level, tissue_level : float
        Normalised-intensity levels used.
    motion : ndarray (h, w)
        Smoothed temporal standard deviation (for figures).
    notes : list of str
    """

    masks: np.ndarray
    roi: tuple[int, int, int, int]
    area_px: np.ndarray
    ok: np.ndarray
    flags: list
    left_edge: np.ndarray
    right_edge: np.ndarray
    axis: tuple[float, float]
    left_px: np.ndarray
    right_px: np.ndarray
    threshold: float
    dark_level: float
    tissue_level: float
    motion: np.ndarray
    notes: list = field(default_factory=list)


def _sample_idx(n: int, k: int = 300) -> np.ndarray:
    return np.unique(np.linspace(0, n - 1, min(n, k)).round().astype(int))


def find_roi(frames: np.ndarray, pad_frac: float = 0.3, min_pad: int = 10):
    """Region of interest from the temporal standard deviation.

    Parameters
    ----------
    frames : ndarray (n, h, w)
        Grey frames.
    pad_frac, min_pad
        Padding of the motion core's bounding box (fraction of its size, pixels).

    Returns
    -------
    roi : (r0, r1, c0, c1)
    core : bool ndarray (h, w)
        The motion core.
    motion : ndarray (h, w)
        Smoothed temporal standard deviation.

    Raises
    ------
    VideoError
        When nothing in the video moves clearly above the noise.
    """
    n, h, w = frames.shape
    if n < 3:
        raise VideoError(f"need at least 3 frames to find the moving glottis, got {n}")
    sub = frames[_sample_idx(n)]
    sd = sub.std(axis=0, dtype=np.float64)
    motion = ndimage.gaussian_filter(sd, 2.0)
    noise = float(np.median(motion))
    peak = float(motion.max())
    rng = float(
        np.percentile(sub[:: max(1, len(sub) // 10)], 99.5) - np.percentile(sub[:: max(1, len(sub) // 10)], 0.5)
    )
    if not (peak > 4.0 * noise and peak > 0.02 * max(rng, 1e-12)):
        raise VideoError(
            "no visible opening: nothing in the video oscillates clearly above the noise "
            f"(max temporal s.d. {peak:.3g} vs median {noise:.3g}); is the glottis in view?"
        )
    thr = noise + 0.25 * (peak - noise)
    lab, nl = ndimage.label(motion > thr)
    score = ndimage.sum(motion, lab, index=np.arange(1, nl + 1))
    core = lab == (1 + int(np.argmax(score)))
    rows = np.flatnonzero(core.any(1))
    cols = np.flatnonzero(core.any(0))
    ph = max(min_pad, int(pad_frac * (rows[-1] - rows[0] + 1)))
    pw = max(min_pad, int(pad_frac * (cols[-1] - cols[0] + 1)), ph // 2)
    roi = (max(0, rows[0] - ph), min(h, rows[-1] + 1 + ph), max(0, cols[0] - pw), min(w, cols[-1] + 1 + pw))
    return roi, core, motion


def _normalise(stack: np.ndarray):
    """Divide by the per-pixel tissue level and a per-frame gain -> (r, gain)."""
    idx = _sample_idx(stack.shape[0])
    b0 = np.percentile(stack[idx], 90, axis=0).astype(np.float64)
    ref = ndimage.gaussian_filter(b0, 15.0)
    valid = b0 > 0.6 * ref
    b = b0.copy()
    if not valid.all():
        for sigma in (6.0, 15.0, 40.0):
            num = ndimage.gaussian_filter(b0 * valid, sigma)
            den = ndimage.gaussian_filter(valid.astype(float), sigma)
            fill = ~valid & (den > 1e-3)
            b[fill] = num[fill] / den[fill]
            valid = valid | fill
            if valid.all():
                break
    b = np.maximum(b, 1e-6 * max(float(b.max()), 1e-12))
    med_b = float(np.median(b))
    gain = np.median(stack.reshape(stack.shape[0], -1), axis=1) / med_b
    gain = np.where(gain > 0, gain, 1.0)
    r = stack / (b[None] * gain[:, None, None].astype(np.float32))
    return r.astype(np.float32), gain


def _segment_roi(stack: np.ndarray, core: np.ndarray):
    r, gain = _normalise(stack)
    core_d = ndimage.binary_dilation(core, iterations=3)
    idx = _sample_idx(r.shape[0])
    rc = r[idx][:, core_d]
    tissue = float(np.median(r[idx]))
    p1 = float(np.percentile(rc, 1.0))
    # dark level: median of the clearly dark core pixels (interior of the open glottis);
    # the 1st percentile alone would sit in the dark tail and bias the threshold low
    dark = float(np.median(rc[rc < p1 + 0.25 * (tissue - p1)]))
    if tissue - dark < 0.12 * tissue:
        raise VideoError(
            "no visible opening: the moving region is not clearly darker than the tissue "
            f"(normalised levels dark {dark:.2f}, tissue {tissue:.2f})"
        )
    thr = dark + 0.5 * (tissue - dark)
    seed_thr = dark + 0.25 * (tissue - dark)
    lab, _ = ndimage.label(r < thr, structure=ndimage.generate_binary_structure(3, 1))
    keep = np.unique(lab[(r < seed_thr) & core_d[None]])
    keep = keep[keep > 0]
    masks = np.isin(lab, keep)
    for i in range(masks.shape[0]):
        if masks[i].any():
            masks[i] = ndimage.binary_fill_holes(masks[i])
    return masks, gain, thr, dark, tissue


def _edges(masks: np.ndarray, c0: int):
    n, hr, wr = masks.shape
    has = masks.any(axis=2)
    left = np.argmax(masks, axis=2).astype(float) + c0
    right = (wr - np.argmax(masks[:, :, ::-1], axis=2)).astype(float) + c0
    left[~has] = np.nan
    right[~has] = np.nan
    return left, right


def _axis(masks: np.ndarray, r0: int, c0: int, k: int = 3):
    union = masks.any(axis=0)
    rows = np.flatnonzero(union.any(axis=1))
    if rows.size < 2:
        return (float(c0 + masks.shape[2] / 2), 0.0)
    wr = union.shape[1]
    lo = np.argmax(union, axis=1)
    hi = wr - np.argmax(union[:, ::-1], axis=1)
    mid = 0.5 * (lo + hi)

    def end(sel):
        return float(np.mean(sel + 0.5)), float(np.mean(mid[sel]))

    (ya, xa), (yb, xb) = end(rows[:k]), end(rows[-k:])
    b = (xb - xa) / (yb - ya) if yb != ya else 0.0
    a_roi = xa - b * ya
    # absolute coordinates: col = a + b * row
    return (float(a_roi + c0 - b * r0), float(b))


def segment_frames(frames: np.ndarray, roi=None, max_grow: int = 3) -> Segmentation:
    """Segment the glottal opening in every frame.

    Parameters
    ----------
    frames : ndarray (n, h, w)
        Grey frames (any intensity scale; the opening must be darker than tissue).
    roi : (r0, r1, c0, c1), optional
        Fixed region of interest; found automatically (:func:`find_roi`) if omitted.
    max_grow : int
        How often the automatic ROI may grow when the opening touches its border.

    Raises
    ------
    VideoError
        No visible opening (nothing oscillates, no dark region, or the segmented area
        is zero in every frame).
    """
    frames = np.asarray(frames, dtype=np.float32)
    if frames.ndim != 3:
        raise VideoError(f"frames must be (n, h, w), got shape {frames.shape}")
    n, h, w = frames.shape
    auto = roi is None
    roi_found, core_full, motion = find_roi(frames)
    if auto:
        roi = roi_found
    else:
        r0, r1, c0, c1 = (int(v) for v in roi)
        if not (0 <= r0 < r1 <= h and 0 <= c0 < c1 <= w):
            raise VideoError(f"ROI {roi} is outside the {w}x{h} frame")
        roi = (r0, r1, c0, c1)
    notes = []
    for _ in range(max_grow + 1):
        r0, r1, c0, c1 = roi
        core = core_full[r0:r1, c0:c1]
        if not core.any():
            raise VideoError(f"ROI {roi} does not contain the oscillating region")
        masks, gain, thr, dark, tissue = _segment_roi(frames[:, r0:r1, c0:c1], core)
        top, bot = masks[:, 0, :].any(), masks[:, -1, :].any()
        lef, rig = masks[:, :, 0].any(), masks[:, :, -1].any()
        if not auto or not (top and r0 > 0 or bot and r1 < h or lef and c0 > 0 or rig and c1 < w):
            break
        gh, gw = max(10, (r1 - r0) // 4), max(10, (c1 - c0) // 4)
        roi = (
            max(0, r0 - gh) if top else r0,
            min(h, r1 + gh) if bot else r1,
            max(0, c0 - gw) if lef else c0,
            min(w, c1 + gw) if rig else c1,
        )
        notes.append(f"ROI grown to {roi} (opening touched the border)")
    area = masks.sum(axis=(1, 2)).astype(float)
    if area.max() <= 0:
        raise VideoError("no visible opening: the segmented glottal area is zero in every frame")
    _check_darker(frames, masks, area, roi)
    ok, flags = _quality_flags(masks, area, gain)

    left, right = _edges(masks, c0)
    a, b = _axis(masks, r0, c0)
    rows_c = np.arange(r0, r1) + 0.5
    m = a + b * rows_c  # axis column per ROI row
    cols = np.arange(c0, c1, dtype=float)
    wl = np.clip(m[:, None] - cols[None, :], 0.0, 1.0)  # fraction of each pixel left of the axis
    left_px = np.tensordot(masks, wl, axes=([1, 2], [0, 1]))
    right_px = area - left_px
    return Segmentation(
        masks=masks,
        roi=tuple(int(v) for v in roi),
        area_px=area,
        ok=ok,
        flags=flags,
        left_edge=left,
        right_edge=right,
        axis=(a, b),
        left_px=left_px,
        right_px=right_px,
        threshold=thr,
        dark_level=dark,
        tissue_level=tissue,
        motion=motion,
        notes=notes,
    )


def _check_darker(frames: np.ndarray, masks: np.ndarray, area: np.ndarray, roi) -> None:
    """VideoError unless the opening, in the frame where it is largest, is darker than the tissue around it
    in that frame (a pulsing highlight only looks dark relative to its own brightest state)."""
    im = int(np.argmax(area))
    m = masks[im]
    ring = ndimage.binary_dilation(m, iterations=4) & ~m
    crop = frames[im, roi[0] : roi[1], roi[2] : roi[3]]
    inside, around = float(np.median(crop[m])), float(np.median(crop[ring])) if ring.any() else float("inf")
    if not inside < 0.8 * around:
        raise VideoError(
            "no visible opening: the segmented region is not darker than the tissue around it "
            f"(median grey {inside:.3g} inside vs {around:.3g} around)"
        )


def _quality_flags(masks: np.ndarray, area: np.ndarray, gain: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Per frame: ok (n,) and the flags that are set ("roi_border", "area_jump", "exposure", comma-separated)."""
    n = masks.shape[0]
    border = masks[:, 0, :].any(1) | masks[:, -1, :].any(1) | masks[:, :, 0].any(1) | masks[:, :, -1].any(1)
    # area jump: residual against the mean of the two neighbouring frames
    pad = np.concatenate([[area[0]], area, [area[-1]]])
    res = area - 0.5 * (pad[:-2] + pad[2:])
    mad = 1.4826 * float(np.median(np.abs(res - np.median(res))))
    jump = (np.abs(res) > 5.0 * mad) & (np.abs(res) > 0.2 * area.max())
    expo = np.abs(gain / np.median(gain) - 1.0) > 0.3
    ok = ~(border | jump | expo)
    flags = [
        ",".join(name for name, f in (("roi_border", border[i]), ("area_jump", jump[i]), ("exposure", expo[i])) if f)
        for i in range(n)
    ]
    return ok, flags
