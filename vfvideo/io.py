"""Reading videos and image stacks.

Videos: any container imageio/ffmpeg reads (mp4, avi, mov, mkv, ...). Stacks: a
folder of PNG/TIFF/JPEG/BMP frames (natural sort of the file names), a multi-page
TIFF, or a ``.npy`` array of shape (n, h, w) or (n, h, w, 3).

GAW files (read_gaw, write_gaw_csv, GawData, GawFileError) are :mod:`vfcore.gawio`'s, re-exported here.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vfcore.gawio import GawData, GawFileError, read_gaw, write_gaw_csv

__all__ = [
    "VideoError",
    "GawFileError",
    "Frames",
    "GawData",
    "read_frames",
    "read_gaw",
    "write_gaw_csv",
    "IMAGE_EXTENSIONS",
]

IMAGE_EXTENSIONS = (".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp")
_LUMA = np.array([0.299, 0.587, 0.114], dtype=np.float32)


class VideoError(ValueError):
    """A video or image stack cannot be turned into a GAW (with the reason)."""


@dataclass
class Frames:
    """Grey-scale frames (n, h, w), float32, original grey-level scale.

    ``meta_fps`` is the container's nominal frame rate (often the playback rate,
    not the capture rate: it is only reported, never used for calibration).
    """

    data: np.ndarray
    source: str
    meta_fps: float | None = None
    color: bool = False


def _to_gray(frame: np.ndarray) -> np.ndarray:
    f = np.asarray(frame)
    if f.ndim == 3 and f.shape[-1] in (3, 4):
        return f[..., :3].astype(np.float32) @ _LUMA
    if f.ndim == 3 and f.shape[-1] == 1:
        return f[..., 0].astype(np.float32)
    if f.ndim != 2:
        raise VideoError(f"frame has unsupported shape {f.shape}")
    return f.astype(np.float32)


def _natural_key(name: str):
    return [int(p) if p.isdigit() else p.lower() for p in re.split(r"(\d+)", name)]


def _stack(frames_iter, source: str) -> tuple[np.ndarray, bool]:
    out = []
    shape0 = None
    color = False
    for i, fr in enumerate(frames_iter):
        fr = np.asarray(fr)
        color = color or (fr.ndim == 3 and fr.shape[-1] in (3, 4))
        g = _to_gray(fr)
        if shape0 is None:
            shape0 = g.shape
        elif g.shape != shape0:
            raise VideoError(
                f"{source}: frames of different sizes: frame {i} is {g.shape[1]}x{g.shape[0]} "
                f"but frame 0 is {shape0[1]}x{shape0[0]} (width x height)"
            )
        out.append(g)
    if not out:
        raise VideoError(f"{source}: contains no frames")
    return np.stack(out), color


def read_frames(source, max_frames: int | None = None) -> Frames:
    """Read a video, an image folder, a multi-page TIFF, a ``.npy`` stack or an array.

    Parameters
    ----------
    source : str, Path or ndarray
        Path, or an array (n, h, w) / (n, h, w, 3).
    max_frames : int, optional
        Read at most this many frames.

    Returns
    -------
    Frames

    Raises
    ------
    VideoError
        Unreadable file, no frames, frames of different sizes.
    """
    if isinstance(source, np.ndarray) or isinstance(source, (list, tuple)):
        return _frames_of_array(source, max_frames)
    path = Path(source)
    src = str(path)
    if not path.exists():
        raise VideoError(f"cannot read '{src}': no such file or directory")
    if path.is_dir():
        return _frames_of_folder(path, src, max_frames)
    if path.suffix.lower() == ".npy":
        return _frames_of_npy(path, src, max_frames)
    return _frames_of_video(path, src, max_frames)


def _frames_of_array(source, max_frames: int | None) -> Frames:
    """Frames from an array (n, h, w) / (n, h, w, 3) or a list of frames."""
    if isinstance(source, (list, tuple)):
        it = source
    else:
        arr = source
        if arr.ndim == 2:
            raise VideoError("array input must be a stack of frames (n, h, w), got one 2D image")
        it = arr
    it = list(it)[:max_frames] if max_frames else it
    data, color = _stack(it, "array")
    return Frames(data=data, source="array", color=color)


def _frames_of_folder(path: Path, src: str, max_frames: int | None) -> Frames:
    """Frames from a folder of image files, in natural order of their names."""
    files = sorted(
        (p for p in path.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS), key=lambda p: _natural_key(p.name)
    )
    if not files:
        raise VideoError(f"{src}: folder contains no frames (no {'/'.join(IMAGE_EXTENSIONS)} files)")
    if max_frames:
        files = files[:max_frames]
    import imageio.v3 as iio

    def gen():
        for f in files:
            try:
                yield iio.imread(f)
            except Exception as e:  # noqa: BLE001 - report which file
                raise VideoError(f"cannot read frame file '{f}': {e}") from e

    data, color = _stack(gen(), src)
    return Frames(data=data, source=src, color=color)


def _frames_of_npy(path: Path, src: str, max_frames: int | None) -> Frames:
    """Frames from a ``.npy`` stack (n, h, w) or (n, h, w, 3)."""
    try:
        arr = np.load(path, allow_pickle=False)
    except Exception as e:  # noqa: BLE001
        raise VideoError(f"cannot read '{src}': {e}") from e
    if arr.ndim not in (3, 4):
        raise VideoError(f"{src}: expected a frame stack (n, h, w) or (n, h, w, 3), got shape {arr.shape}")
    data, color = _stack(arr[:max_frames] if max_frames else arr, src)
    return Frames(data=data, source=src, color=color)


def _frames_of_video(path: Path, src: str, max_frames: int | None) -> Frames:
    """Frames from a video or multi-page image file (imageio), with the frame rate of its metadata if any."""
    if path.stat().st_size == 0:
        raise VideoError(f"cannot read '{src}': the file is empty")
    import imageio.v3 as iio

    meta_fps = None
    try:
        meta = iio.immeta(path)
        v = meta.get("fps")
        meta_fps = float(v) if v is not None and math.isfinite(float(v)) else None
    except Exception:  # noqa: BLE001 - metadata is optional
        pass

    def gen():
        try:
            for i, fr in enumerate(iio.imiter(path)):
                if max_frames and i >= max_frames:
                    return
                yield fr
        except VideoError:
            raise
        except Exception as e:  # noqa: BLE001 - any decoder failure is an unreadable file
            raise VideoError(f"cannot read '{src}' as a video or image stack: {type(e).__name__}: {e}") from e

    data, color = _stack(gen(), src)
    if data.shape[0] == 1 and path.suffix.lower() in IMAGE_EXTENSIONS:
        raise VideoError(f"{src}: a single image, not a video; pass a folder of frames or a multi-page TIFF")
    return Frames(data=data, source=src, meta_fps=meta_fps, color=color)
