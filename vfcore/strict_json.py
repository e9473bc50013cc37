"""Strict JSON from numpy-laden data: what a summary, a report or a table becomes before it is written.

JSON has no NaN or infinity (RFC 8259, section 6) and no numpy types, while the library's results carry
both; one conversion, shared by the library's tables, the worker's summaries and the service's reports,
keeps every file the product writes readable by any JSON parser.
"""

from __future__ import annotations

import math

import numpy as np


def jsonable(obj):
    """A strict-JSON copy of ``obj``: dict keys to str, tuples and arrays to lists, numpy scalars to Python,
    non-finite floats to None; any other object to its ``str``."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return x if math.isfinite(x) else None
    if obj is None or isinstance(obj, str):
        return obj
    return str(obj)
