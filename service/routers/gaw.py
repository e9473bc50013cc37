"""POST /gaw: a high-speed video (or image stack) in, a calibrated GAW out.

The returned ``gaw`` object has the shape a job spec expects (areas in mm^2, fps), so a
client can submit it to POST /jobs as is. Upload size is bounded by the app's body
limit; the file is written to a server-chosen temporary name (no path from user input)
and deleted afterwards.
"""

from __future__ import annotations

import asyncio
import math
import tempfile
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, File, Form, HTTPException, UploadFile

from ..deps import UserDep

router = APIRouter(tags=["gaw"])

#: File types vfvideo reads; the suffix is taken from this list, never from the client.
SUFFIXES = {".mp4", ".avi", ".mov", ".mkv", ".tif", ".tiff", ".npy"}


def _extract(path: Path, fps: float, px_per_mm: float, segment_s: float) -> dict:
    from vfvideo import extract_gaw

    ex = extract_gaw(path, fps=fps, px_per_mm=px_per_mm, segment_s=segment_s)
    s = ex.summary()
    return {
        "gaw": {"areas": [float(a) for a in ex.segment_area], "fps": float(ex.fps), "units": "mm2"},
        "f0_hz": float(ex.f0),
        "n_frames": int(ex.area.size),
        "n_flagged_frames": int((~ex.ok).sum()),
        "segment": [int(ex.segment[0]), int(ex.segment[1])],
        "measures": {
            k: (float(v) if isinstance(v, (int, float)) and math.isfinite(float(v)) else None)
            for k, v in ex.measures.items()
            if isinstance(v, (int, float))
        },
        "notes": s.get("notes", []),
    }


@router.post("/gaw", summary="Extract a glottal area waveform from an uploaded high-speed video")
async def gaw_from_video(
    user: UserDep,
    video: Annotated[UploadFile, File(description="video (mp4/avi/mov/mkv), multi-page TIFF or .npy stack")],
    fps: Annotated[float, Form(gt=0, le=1e6, description="capture frame rate, frames/s")],
    px_per_mm: Annotated[float, Form(gt=0, le=1e4, description="spatial calibration, pixels per mm")],
    segment_s: Annotated[float, Form(gt=0, le=10)] = 0.3,
) -> dict:
    suffix = Path(video.filename or "").suffix.lower()
    if suffix not in SUFFIXES:
        raise HTTPException(422, f"video: unsupported file type {suffix!r}; use one of {sorted(SUFFIXES)}")
    del user  # authenticated; extraction stores nothing per user
    with tempfile.TemporaryDirectory(prefix="vfinfer-gaw-") as tmp:
        path = Path(tmp) / f"upload{suffix}"
        path.write_bytes(await video.read())
        try:
            return await asyncio.to_thread(_extract, path, fps, px_per_mm, segment_s)
        except ValueError as exc:  # vfvideo's VideoError / bad calibration: a clear 422
            raise HTTPException(422, f"video: {exc}") from None
