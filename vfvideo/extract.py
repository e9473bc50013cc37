"""Video -> calibrated glottal area waveform, stable segment, f0 and GAW measures."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vfcore.measures import estimate_f0, gaw_measures

from .io import Frames, read_frames, write_gaw_csv
from .segment import Segmentation, segment_frames

__all__ = ["GawExtraction", "extract_gaw", "select_segment"]


@dataclass
class GawExtraction:
    """A GAW extracted from a video.

    Attributes
    ----------
    t : ndarray (n,)
        Frame times (s), ``arange(n) / fps``.
    area : ndarray (n,)
        Glottal area (mm^2) = pixel count x pixel area, every frame.
    area_left, area_right : ndarray (n,)
        Parts of the area left / right of the glottal main axis (mm^2).
    ok : bool ndarray (n,)
        Per-frame quality; ``flags`` gives the reasons.
    fps, px_per_mm, pixel_area_mm2 : float
        Calibration.
    segment : (start, stop)
        Frames of the selected stable segment (``area[start:stop]``).
    f0 : float
        f0 of the segment (Hz), NaN if not periodic.
    measures : dict
        :func:`vfcore.measures.gaw_measures` of the segment.
    seg : Segmentation
        Masks, ROI, edges (pixels).
    thumbs : list of (frame index, ROI grey crop, ROI mask)
        A few frames of one cycle, for figures.
    source : str
    meta_fps : float or None
        Frame rate stored in the container (reported only).
    notes : list of str
    """

    t: np.ndarray
    area: np.ndarray
    area_left: np.ndarray
    area_right: np.ndarray
    ok: np.ndarray
    flags: list
    fps: float
    px_per_mm: float
    pixel_area_mm2: float
    segment: tuple[int, int]
    f0: float
    measures: dict
    seg: Segmentation
    thumbs: list
    source: str
    meta_fps: float | None = None
    notes: list = field(default_factory=list)

    @property
    def segment_t(self) -> np.ndarray:
        """Times of the segment, starting at 0 (s)."""
        a, b = self.segment
        return self.t[a:b] - self.t[a]

    @property
    def segment_area(self) -> np.ndarray:
        """Areas of the segment (mm^2)."""
        a, b = self.segment
        return self.area[a:b]

    def asymmetry(self) -> float:
        """Left-right amplitude asymmetry (A_L - A_R) / (A_L + A_R) of the segment's
        peak-to-peak half areas (dimensionless; 0 = symmetric)."""
        a, b = self.segment
        al = np.ptp(self.area_left[a:b])
        ar = np.ptp(self.area_right[a:b])
        return float((al - ar) / (al + ar)) if al + ar > 0 else float("nan")

    def write_csv(self, path, full: bool = False) -> Path:
        """Write the GAW (the stable segment, or every frame with ``full=True``) as a
        CSV that :func:`vfvideo.io.read_gaw`, the CLI and the service read."""
        a, b = (0, self.area.size) if full else self.segment
        meta = {
            "source": self.source,
            "px_per_mm": f"{self.px_per_mm:.10g}",
            "pixel_area_mm2": f"{self.pixel_area_mm2:.6g}",
            "segment_frames": f"{a}-{b}" + (" (full video)" if full else " of the video"),
            "f0_hz": f"{self.f0:.6g}",
            "frames_flagged": int(np.sum(~self.ok[a:b])),
            "roi_rows_cols": "{}:{},{}:{}".format(*self.seg.roi),
        }
        return write_gaw_csv(path, self.t[a:b] - self.t[a], self.area[a:b], self.fps, meta=meta)

    def summary(self) -> dict:
        """JSON-friendly summary (no arrays)."""
        return {
            "source": self.source,
            "n_frames": int(self.area.size),
            "fps": self.fps,
            "meta_fps": self.meta_fps,
            "px_per_mm": self.px_per_mm,
            "pixel_area_mm2": self.pixel_area_mm2,
            "roi": list(self.seg.roi),
            "segment": list(self.segment),
            "segment_s": (self.segment[1] - self.segment[0]) / self.fps,
            "f0_hz": self.f0,
            "frames_flagged": int(np.sum(~self.ok)),
            "asymmetry": self.asymmetry(),
            "measures": self.measures,
            "notes": list(self.notes) + list(self.seg.notes),
        }


def _periodicity(x: np.ndarray, fps: float, fmin: float, fmax: float) -> float:
    """Highest normalised autocorrelation in the pitch-lag range (0..1)."""
    x = x - x.mean()
    e = float(np.dot(x, x))
    if e <= 0:
        return 0.0
    lo = max(1, int(fps / fmax))
    hi = min(x.size - 2, int(math.ceil(fps / fmin)))
    best = 0.0
    for lag in range(lo, hi + 1):
        a, b = x[:-lag], x[lag:]
        d = math.sqrt(float(np.dot(a, a)) * float(np.dot(b, b)))
        if d > 0:
            best = max(best, float(np.dot(a, b)) / d)
    return best


def select_segment(
    area: np.ndarray, ok: np.ndarray, fps: float, duration_s: float = 0.3, fmin: float = 40.0, fmax: float = 600.0
) -> tuple[tuple[int, int], list[str]]:
    """Choose the most stable window of ``duration_s`` (default 300 ms as in the paper).

    Windows start every ~1/10 window; the one with the fewest flagged frames wins,
    ties broken by the highest periodicity (autocorrelation peak). Nothing is
    detrended or rescaled. If the video is shorter, the whole video is used (noted).
    """
    n = area.size
    notes = []
    w = int(round(duration_s * fps))
    if w >= n:
        if w > n:
            notes.append(
                f"video ({n / fps * 1e3:.1f} ms) shorter than the requested {duration_s * 1e3:.0f} ms "
                "segment: whole video used"
            )
        return (0, n), notes
    step = max(1, w // 10)
    starts = list(range(0, n - w + 1, step))
    if starts[-1] != n - w:
        starts.append(n - w)
    bad = np.concatenate([[0], np.cumsum(~ok)])
    best, best_key = (0, w), None
    for s in starts:
        key = (-(bad[s + w] - bad[s]), _periodicity(area[s : s + w], fps, fmin, fmax))
        if best_key is None or key > best_key:
            best, best_key = (s, s + w), key
    return best, notes


def _thumbs(frames: np.ndarray, seg: Segmentation, segment, fps: float, f0: float, k: int = 4):
    r0, r1, c0, c1 = seg.roi
    a, b = segment
    area = seg.area_px
    if math.isfinite(f0):
        P = fps / f0
        i0 = a + int(np.argmin(area[a : min(b, a + int(math.ceil(P)) + 1)]))
        idx = [min(b - 1, int(round(i0 + j * P / k))) for j in range(k)]
    else:
        idx = list(np.linspace(a, b - 1, k).round().astype(int))
    return [(int(i), frames[i, r0:r1, c0:c1].copy(), seg.masks[i].copy()) for i in idx]


def extract_gaw(
    source,
    fps: float,
    px_per_mm: float,
    *,
    roi=None,
    segment_s: float = 0.3,
    max_frames: int | None = None,
    fmin: float = 40.0,
    fmax: float = 600.0,
) -> GawExtraction:
    """Segment the glottis in a video or image stack and return the calibrated GAW.

    Parameters
    ----------
    source : str, Path, ndarray or Frames
        Video file (mp4/avi/... via imageio-ffmpeg), folder of PNG/TIFF frames,
        multi-page TIFF, ``.npy`` stack, or an array (n, h, w[, 3]).
    fps : float
        Capture frame rate (Hz), e.g. 2000 in the paper. Required: container rates
        are often playback rates.
    px_per_mm : float
        Spatial calibration (pixels per mm), e.g. 24.4; pixel area = 1/px_per_mm^2 mm^2.
    roi : (r0, r1, c0, c1), optional
        Region of interest (rows r0:r1, columns c0:c1); automatic if omitted.
    segment_s : float
        Length of the stable segment to report (s); 0.3 as in the paper.
    max_frames : int, optional
        Read at most this many frames.
    fmin, fmax : float
        f0 search range (Hz).

    Returns
    -------
    GawExtraction

    Raises
    ------
    ValueError
        fps or px_per_mm not a positive finite number.
    VideoError (a ValueError)
        Unreadable input, no frames, frames of different sizes, no visible opening.
    """
    for name, v in (("fps", fps), ("px_per_mm", px_per_mm)):
        try:
            fv = float(v)
        except (TypeError, ValueError):
            raise ValueError(f"{name} must be a number, got {v!r}") from None
        if not (math.isfinite(fv) and fv > 0):
            raise ValueError(f"{name} must be > 0, got {v}")
    fps, px_per_mm = float(fps), float(px_per_mm)
    fr = source if isinstance(source, Frames) else read_frames(source, max_frames=max_frames)
    frames = fr.data
    seg = segment_frames(frames, roi=roi)
    pa = 1.0 / px_per_mm**2
    area = seg.area_px * pa
    notes = []
    if fr.meta_fps and abs(fr.meta_fps - fps) > 1e-6 * fps:
        notes.append(f"container frame rate {fr.meta_fps:g} fps ignored; calibration uses fps={fps:g}")
    segment, n2 = select_segment(area, seg.ok, fps, segment_s, fmin, fmax)
    notes += n2
    a, b = segment
    f0 = estimate_f0(area[a:b], fps, fmin, fmax)
    if not math.isfinite(f0):
        notes.append("segment shows no periodic oscillation: f0 and cycle measures are NaN")
    try:
        measures = gaw_measures(area[a:b], fps)
    except ValueError as e:
        measures = {}
        notes.append(f"measures not computed: {e}")
    return GawExtraction(
        t=np.arange(area.size) / fps,
        area=area,
        area_left=seg.left_px * pa,
        area_right=seg.right_px * pa,
        ok=seg.ok,
        flags=seg.flags,
        fps=fps,
        px_per_mm=px_per_mm,
        pixel_area_mm2=pa,
        segment=segment,
        f0=f0,
        measures=measures,
        seg=seg,
        thumbs=_thumbs(frames, seg, segment, fps, f0),
        source=fr.source,
        meta_fps=fr.meta_fps,
        notes=notes,
    )
