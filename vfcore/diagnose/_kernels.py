"""Numba kernels of the diagnosis' observation models (vfcore.diagnose.fit)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def strip_sum(y, delays, weights):
    """``sum_k weights[k] * y(i - delays[k])`` for ``i = 0..n-1``: ``y`` read at a delay of
    ``delays[k]`` samples (any real) by linear interpolation, its end values held outside
    ``0..n-1`` (as ``np.interp`` holds them). One pass over ``y`` per delay: for a delay ``d``,
    with ``m = floor(-d)`` and ``f = -d - m``, sample ``i`` reads ``(1 - f) y[i + m] + f y[i + m + 1]``
    inside the record and an end value outside it."""
    n = y.size
    out = np.zeros(n)
    for k in range(delays.size):
        w = weights[k]
        if w == 0.0:
            continue
        m = int(math.floor(-delays[k]))
        f = -delays[k] - m
        a = min(max(-m, 0), n)  # i < a: before the record's start (t < 0)
        b = max(min(n - 1 - m, n), a)  # a <= i < b: inside; i >= b: at or past its end
        y0 = w * y[0]
        for i in range(a):
            out[i] += y0
        w0 = w * (1.0 - f)
        w1 = w * f
        o = out[a:b]  # slices indexed from 0: no negative-index checks in the loop
        y_lo = y[a + m : b + m]
        y_hi = y[a + m + 1 : b + m + 1]
        for j in range(b - a):
            o[j] += w0 * y_lo[j] + w1 * y_hi[j]
        yn = w * y[n - 1]
        for i in range(b, n):
            out[i] += yn
    return out
