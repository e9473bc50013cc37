"""High-speed video -> glottal area waveform.

>>> from vfvideo import extract_gaw
>>> ex = extract_gaw("clip.mp4", fps=2000, px_per_mm=24.4)
>>> ex.write_csv("gaw.csv"); ex.f0, ex.measures

See ``:ref:`video`.
"""

from .extract import GawExtraction, extract_gaw, select_segment
from .figure import plot_extraction
from .io import Frames, GawData, GawFileError, VideoError, read_frames, read_gaw, write_gaw_csv
from .segment import Segmentation, find_roi, segment_frames

__all__ = [
    "extract_gaw",
    "GawExtraction",
    "select_segment",
    "plot_extraction",
    "read_frames",
    "read_gaw",
    "write_gaw_csv",
    "Frames",
    "GawData",
    "VideoError",
    "GawFileError",
    "Segmentation",
    "find_roi",
    "segment_frames",
]
