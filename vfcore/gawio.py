"""Reading and writing glottal area waveform (GAW) files: the format the library consumes and writes.

GAW files
---------
CSV written by :func:`write_gaw_csv`::

    # vfinfer GAW v1
    # fps: 2000
    # time_unit: s
    # area_unit: mm^2
    time_s,area_mm2
    0.0000000,1.234567
    ...

:func:`read_gaw` also accepts other CSVs (a header with a time column and an area
column, or a single area column), ``.npy`` (1D area, or (n, 2) time and area) and
``.npz`` (keys ``area`` and ``t`` or ``fps``). Units come from the file (``# area_unit:``
comments, or column names such as ``area_mm2``, ``area_px``, ``time_ms``) or from
arguments, which take precedence.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["GawFileError", "GawData", "NEGATIVE_NOISE_SDS", "check_negative", "noise_sd", "read_gaw", "write_gaw_csv"]

#: Negative areas down to this many noise sds below zero are measurement noise around a closed glottis and are
#: kept as they are (the likelihood's Gaussian noise expects them; clipping them to 0 would bias every closed
#: phase upwards); anything deeper is refused as a baseline error. The noise sd is estimated from the
#: recording's second differences, which the GAW's smooth waveform barely reaches (so the estimate errs high).
NEGATIVE_NOISE_SDS = 5.0


#: 1 / Phi^-1(3/4): the MAD of a normal sample times this is its sd
MAD_TO_SD = 1.482602218505602


def noise_sd(area) -> float:
    """Robust noise sd of a recording (mm^2): MAD of second differences / sqrt(6), which for white noise
    of sd s has sd s*sqrt(6)."""
    d2 = np.diff(np.asarray(area, dtype=float), 2)
    if d2.size == 0:
        return 0.0
    return float(MAD_TO_SD * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6.0))


def check_negative(area) -> str | None:
    """None when no sample of ``area`` lies below ``-NEGATIVE_NOISE_SDS`` noise sds (:func:`noise_sd`);
    else the reason, one sentence without the source's name (the caller prefixes the file or field)."""
    a = np.asarray(area, dtype=float)
    neg = a < 0
    if not neg.any():
        return None
    sd = noise_sd(a)
    deepest = float(a.min())
    if deepest >= -NEGATIVE_NOISE_SDS * sd:
        return None
    return (
        f"{int(neg.sum())} negative areas down to {deepest:.3g} mm^2, beyond the recording's noise "
        f"({NEGATIVE_NOISE_SDS:g} x {sd:.3g} mm^2): an area cannot be negative; check the baseline subtraction"
    )


class GawFileError(ValueError):
    """A GAW file cannot be read (with the reason)."""


_AREA_TO_MM2 = {"mm^2": 1.0, "mm2": 1.0, "cm^2": 100.0, "cm2": 100.0, "m^2": 1e6, "m2": 1e6}
_TIME_TO_S = {"s": 1.0, "ms": 1e-3, "us": 1e-6}


@dataclass
class GawData:
    """A GAW read from a file: times (s), area (mm^2), frame rate (Hz), header metadata."""

    t: np.ndarray
    area: np.ndarray
    fps: float
    meta: dict = field(default_factory=dict)


def _norm_unit(u: str) -> str:
    return u.strip().lower().replace("²", "^2").replace(" ", "")


def _area_factor(unit: str, px_per_mm: float | None) -> float:
    u = _norm_unit(unit)
    if u in ("px", "pixel", "pixels", "px^2"):
        if not px_per_mm or px_per_mm <= 0:
            raise GawFileError("area is in pixels: give px_per_mm to convert it to mm^2")
        return 1.0 / px_per_mm**2
    if u not in _AREA_TO_MM2:
        raise GawFileError(f"unknown area unit '{unit}' (use mm^2, cm^2, m^2 or px)")
    return _AREA_TO_MM2[u]


def _time_factor(unit: str) -> float:
    u = _norm_unit(unit)
    if u not in _TIME_TO_S:
        raise GawFileError(f"unknown time unit '{unit}' (use s or ms)")
    return _TIME_TO_S[u]


def _col_unit(name: str, kind: str) -> str | None:
    n = name.strip().lower()
    m = re.match(rf"^{kind}[ _\[(]+([a-z0-9^²]+)[\])]*$", n)
    if m:
        return {"mm2": "mm^2", "cm2": "cm^2", "m2": "m^2", "px2": "px"}.get(m.group(1), m.group(1))
    return None


def read_gaw(
    path,
    fps: float | None = None,
    area_unit: str | None = None,
    time_unit: str | None = None,
    px_per_mm: float | None = None,
    allow_negative: bool = False,
) -> GawData:
    """Read a GAW file (CSV, NPY, NPZ) into times (s) and areas (mm^2).

    Parameters
    ----------
    path : str or Path
    fps : float, optional
        Frame rate (Hz); needed when the file has no time column and no ``# fps:``.
    area_unit, time_unit : str, optional
        Override the units found in the file (defaults mm^2 and s).
    px_per_mm : float, optional
        Calibration for areas given in pixels.
    allow_negative : bool
        Return negative areas instead of refusing them (for a caller that decides which negative
        samples are noise around zero, e.g. the command line's clipping rule).

    Raises
    ------
    GawFileError
        Unreadable or empty file, no area column, non-uniform or missing sampling,
        negative or non-finite areas, fps <= 0.
    """
    p = Path(path)
    if not p.is_file():
        raise GawFileError(f"cannot read GAW '{p}': no such file")
    meta: dict = {}
    if p.suffix.lower() in (".npy", ".npz"):
        t, area, fps = _read_numpy(p, fps, meta)
    else:
        t, area = _read_text(p, meta)
    area_u = area_unit or meta.get("area_unit", "mm^2")
    time_u = time_unit or meta.get("time_unit", "s")
    area = _area_in_mm2(p, area, area_u, px_per_mm, meta, allow_negative)
    t, fps = _times_and_rate(p, t, time_u, fps, meta)
    if t is None:
        t = np.arange(area.size) / fps
    meta["area_unit_in_file"] = area_u
    return GawData(t=t, area=area, fps=float(fps), meta=meta)


def _read_numpy(p: Path, fps: float | None, meta: dict) -> tuple[np.ndarray | None, np.ndarray, float | None]:
    """``(t, area, fps)`` of a ``.npy`` (1D area or (n, 2) time and area) or ``.npz`` file, in the file's
    units; an ``fps`` stored in an npz is used only where none was given. Units found go into ``meta``."""
    try:
        obj = np.load(p, allow_pickle=False)
    except Exception as e:  # noqa: BLE001
        raise GawFileError(f"cannot read GAW '{p}': {e}") from e
    t = None
    if isinstance(obj, np.lib.npyio.NpzFile):
        keys = set(obj.files)
        akey = next((k for k in ("area", "area_mm2", "gaw") if k in keys), None)
        if akey is None:
            raise GawFileError(f"{p}: npz needs an 'area' array (found {sorted(keys)})")
        area = np.asarray(obj[akey], dtype=float)
        if "t" in keys:
            t = np.asarray(obj["t"], dtype=float)
        if "fps" in keys and fps is None:
            fps = float(obj["fps"])
        for k in ("area_unit", "time_unit"):
            if k in keys:
                meta[k] = str(obj[k])
        return t, area, fps
    arr = np.asarray(obj, dtype=float)
    if arr.ndim == 1:
        return None, arr, fps
    if arr.ndim == 2 and arr.shape[1] == 2:
        return arr[:, 0], arr[:, 1], fps
    raise GawFileError(f"{p}: expected a 1D area array or (n, 2) time/area, got shape {arr.shape}")


def _read_text(p: Path, meta: dict) -> tuple[np.ndarray | None, np.ndarray]:
    """``(t, area)`` of a CSV (or whitespace-separated) file in the file's units; its ``# key: value``
    header lines and the units in its column names go into ``meta``."""
    try:
        text = p.read_text()
    except Exception as e:  # noqa: BLE001
        raise GawFileError(f"cannot read GAW '{p}': {e}") from e
    header, rows = _parse_lines(p, text, meta)
    if not rows:
        raise GawFileError(f"{p}: no data rows")
    ncol = len(rows[0])
    if any(len(r) != ncol for r in rows):
        raise GawFileError(f"{p}: rows have different numbers of columns")
    arr = np.asarray(rows, dtype=float)
    names = [h.lower() for h in header] if header else None
    if names is not None and len(names) == ncol:
        return _named_columns(p, arr, header, names, meta)
    if ncol == 1:
        return None, arr[:, 0]
    if ncol == 2:
        return arr[:, 0], arr[:, 1]
    raise GawFileError(f"{p}: {ncol} columns without a header; expected (time, area) or (area)")


def _parse_lines(p: Path, text: str, meta: dict) -> tuple[list[str] | None, list[list[float]]]:
    """The column names (a first non-numeric line, or None) and the numeric rows of ``text``; the
    ``# key: value`` comments go into ``meta`` (keys lower-cased)."""
    header = None
    rows = []
    for line in text.splitlines():
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            m = re.match(r"#\s*([A-Za-z_]+)\s*[:=]\s*(.+)$", s)
            if m:
                meta[m.group(1).strip().lower()] = m.group(2).strip()
            continue
        parts = [q.strip() for q in re.split(r"[,;\t]", s) if q.strip() != ""] if re.search(r"[,;\t]", s) else s.split()
        try:
            rows.append([float(q) for q in parts])
        except ValueError:
            if header is None and not rows:
                header = parts
                continue
            raise GawFileError(f"{p}: non-numeric value in line '{s[:60]}'") from None
    return header, rows


def _named_columns(
    p: Path, arr: np.ndarray, header: list[str], names: list[str], meta: dict
) -> tuple[np.ndarray | None, np.ndarray]:
    """``(t, area)`` chosen by column name (``t...``/``time...``; ``area...``/``gaw...``, else the last of at
    most two columns); units in the names (``area_mm2``, ``time_ms``) go into ``meta`` unless a header
    comment gave them."""
    ncol = arr.shape[1]
    ti = next((i for i, nm in enumerate(names) if nm.startswith("t")), None)
    ai = next((i for i, nm in enumerate(names) if nm.startswith("area") or nm.startswith("gaw")), None)
    if ai is None:
        ai = ncol - 1 if ncol <= 2 else None
    if ai is None:
        raise GawFileError(f"{p}: no area column among {header}")
    area = arr[:, ai]
    t = None
    if ti is not None and ti != ai:
        t = arr[:, ti]
        u = _col_unit(names[ti], "time") or _col_unit(names[ti], "t")
        if u and "time_unit" not in meta:
            meta["time_unit"] = u
    u = _col_unit(names[ai], "area") or _col_unit(names[ai], "gaw")
    if u and "area_unit" not in meta:
        meta["area_unit"] = u
    return t, area


def _area_in_mm2(p: Path, area, area_u: str, px_per_mm: float | None, meta: dict, allow_negative: bool) -> np.ndarray:
    """The areas converted from ``area_u`` to mm^2 (pixels with ``px_per_mm``, else the header's) and checked:
    at least two samples, finite, and non-negative unless ``allow_negative``."""
    if px_per_mm is None and "px_per_mm" in meta:
        try:
            px_per_mm = float(meta["px_per_mm"])
        except ValueError:
            pass
    area = np.asarray(area, dtype=float) * _area_factor(area_u, px_per_mm)
    if area.size < 2:
        raise GawFileError(f"{p}: fewer than two samples")
    if not np.all(np.isfinite(area)):
        raise GawFileError(f"{p}: area contains NaN or infinite values")
    if not allow_negative and np.any(area < 0):
        raise GawFileError(f"{p}: negative areas")
    return area


def _times_and_rate(p: Path, t, time_u: str, fps: float | None, meta: dict) -> tuple[np.ndarray | None, float]:
    """The times in s (None without a time column) and the frame rate (Hz): the one given, else the header's,
    else the time column's, which must be increasing, uniform and agree with a given rate."""
    if fps is None and "fps" in meta:
        try:
            fps = float(meta["fps"])
        except ValueError:
            raise GawFileError(f"{p}: bad fps '{meta['fps']}' in header") from None
    if t is not None:
        t = np.asarray(t, dtype=float) * _time_factor(time_u)
        dt = np.diff(t)
        if np.any(dt <= 0):
            raise GawFileError(f"{p}: time column is not increasing")
        med = float(np.median(dt))
        if np.max(np.abs(dt - med)) > 1e-3 * med + 1e-9:
            raise GawFileError(f"{p}: non-uniform sampling (time steps {dt.min():.3g} .. {dt.max():.3g} s)")
        fps_t = 1.0 / med
        if fps is None:
            fps = fps_t
        elif abs(fps - fps_t) > 1e-3 * fps:
            raise GawFileError(f"{p}: fps {fps:g} disagrees with the time column ({fps_t:g} Hz)")
    if fps is None:
        raise GawFileError(f"{p}: no time column and no fps; give the frame rate")
    if not (math.isfinite(fps) and fps > 0):
        raise GawFileError(f"{p}: frame rate must be > 0, got {fps}")
    return t, fps


def write_gaw_csv(path, t, area, fps: float, meta: dict | None = None, extra: dict | None = None) -> Path:
    """Write a GAW as CSV (``time_s,area_mm2`` plus optional extra columns).

    Parameters
    ----------
    path : str or Path
    t : array_like
        Times in s.
    area : array_like
        Areas in mm^2.
    fps : float
        Frame rate (Hz), written into the header.
    meta : dict, optional
        Extra ``# key: value`` header lines (e.g. source, px_per_mm, segment).
    extra : dict of name -> array, optional
        Extra numeric columns after the two main ones.
    """
    t = np.asarray(t, dtype=float)
    area = np.asarray(area, dtype=float)
    if t.shape != area.shape or t.ndim != 1:
        raise ValueError("t and area must be 1D arrays of the same length")
    if not (fps > 0):
        raise ValueError(f"fps must be > 0, got {fps}")
    p = Path(path)
    if p.parent and not p.parent.exists():
        os.makedirs(p.parent, exist_ok=True)
    cols = [t, area]
    names = ["time_s", "area_mm2"]
    for k, v in (extra or {}).items():
        v = np.asarray(v, dtype=float)
        if v.shape != t.shape:
            raise ValueError(f"extra column '{k}' has the wrong length")
        names.append(k)
        cols.append(v)
    lines = ["# vfinfer GAW v1", f"# fps: {fps:.10g}", "# time_unit: s", "# area_unit: mm^2"]
    for k, v in (meta or {}).items():
        lines.append(f"# {k}: {str(v).replace(chr(10), ' ')}")
    lines.append(",".join(names))
    data = np.column_stack(cols)
    body = "\n".join(",".join(f"{x:.9g}" for x in row) for row in data)
    p.write_text("\n".join(lines) + "\n" + body + "\n")
    return p
