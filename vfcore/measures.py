"""Glottal-area-waveform (GAW) measures, each defined once here.

All functions take a 1D GAW ``gaw`` (area, normally mm^2) sampled at ``fps`` frames
per second and use numpy only. Sources and exact definitions are collected in
``:ref:`measures`; every function's docstring states its units and source. The f0, the
cycle boundaries and the per-cycle timings the measures are built on (and the cycle
convention) are :mod:`vfcore.cycles`; their names are re-exported here.

Cycle measures are averaged (arithmetic mean) over all complete cycles.
"""

from __future__ import annotations

import numpy as np

from .cycles import DEFAULT_LEVEL, as_gaw, cycle_boundaries, cycle_table, estimate_f0

__all__ = [
    "estimate_f0",
    "cycle_boundaries",
    "cycle_table",
    "open_quotient",
    "speed_quotient",
    "closing_quotient",
    "amplitude_quotient",
    "naq",
    "glottal_gap_index",
    "harmonic_amplitudes",
    "harmonic_richness_factor",
    "jitter",
    "shimmer",
    "subharmonic_to_harmonic_ratio",
    "gaw_measures",
    "DEFAULT_LEVEL",
]


def _mean(v: np.ndarray) -> float:
    return float(np.mean(v)) if v.size else float("nan")


def open_quotient(gaw, fps, level: float = DEFAULT_LEVEL) -> float:
    """Open quotient OQ = T_o / T (dimensionless, mean over cycles).

    Source: Timcke, von Leden & Moore (1958), Arch. Otolaryngol. 68:1-19 (open
    quotient from high-speed films); GAW form as in Patel, Dubrovskiy & Döllinger
    (2014), J. Speech Lang. Hear. Res. 57:1151-1163 (note the threshold ``level``).
    """
    t = cycle_table(gaw, fps, level)
    return _mean(t["t_open"] / t["period"])


def speed_quotient(gaw, fps, level: float = DEFAULT_LEVEL) -> float:
    """Speed quotient SQ = T_op / T_cl (opening over closing time; dimensionless).

    Source: Timcke, von Leden & Moore (1958); Holmberg, Hillman & Perkell (1988),
    J. Acoust. Soc. Am. 84:511-529.
    """
    t = cycle_table(gaw, fps, level)
    ok = t["t_closing"] > 0
    return _mean(t["t_opening"][ok] / t["t_closing"][ok])


def closing_quotient(gaw, fps, level: float = DEFAULT_LEVEL) -> float:
    """Closing quotient ClQ = T_cl / T (dimensionless).

    Source: Holmberg, Hillman & Perkell (1988); Alku & Vilkman (1996), Folia
    Phoniatr. Logop. 48:240-254.
    """
    t = cycle_table(gaw, fps, level)
    return _mean(t["t_closing"] / t["period"])


def amplitude_quotient(gaw, fps) -> float:
    """Amplitude quotient AQ = (A_max - A_min) / |min dA/dt| in seconds.

    Source: Alku & Vilkman (1996), Folia Phoniatr. Logop. 48:240-254 (defined on
    the glottal flow; here applied to the area, whose derivative is taken by
    central differences, ``numpy.gradient``).
    """
    t = cycle_table(gaw, fps)
    ok = t["dmin"] < 0
    return _mean((t["a_max"][ok] - t["a_min"][ok]) / -t["dmin"][ok])


def naq(gaw, fps) -> float:
    """Normalised amplitude quotient NAQ = AQ / T (dimensionless, mean over cycles).

    Source: Alku, Bäckström & Vilkman (2002), J. Acoust. Soc. Am. 112:701-710.
    For a sinusoid NAQ = 1/pi; for a linear closing ramp of duration T_cl it equals
    T_cl / T.
    """
    t = cycle_table(gaw, fps)
    ok = t["dmin"] < 0
    return _mean((t["a_max"][ok] - t["a_min"][ok]) / -t["dmin"][ok] / t["period"][ok])


def glottal_gap_index(gaw, fps) -> float:
    """Glottal gap index GGI = A_min / A_max per cycle (dimensionless, 0 = complete closure).

    Source: Patel, Dubrovskiy & Döllinger (2014), J. Speech Lang. Hear. Res.
    57:1151-1163 (Glottis Analysis Tools parameter set).
    """
    t = cycle_table(gaw, fps)
    ok = t["a_max"] > 0
    return _mean(t["a_min"][ok] / t["a_max"][ok])


def _whole_cycle_segment(x: np.ndarray, b: np.ndarray, even: bool) -> tuple[np.ndarray, int]:
    m = b.size - 1
    if even and m % 2:
        m -= 1
    if m < 1:
        return x[:0], 0
    return x[b[0] : b[m]], m


def harmonic_amplitudes(gaw, fps, n_harmonics: int = 10) -> np.ndarray:
    """Amplitudes of harmonics 1..K of f0 (same unit as the GAW).

    The GAW is cut to a whole number ``m`` of cycles (boundary to boundary), so the
    k-th harmonic falls on DFT bin ``k*m``; the amplitude is ``2|X[k m]|/N``. ``K`` is
    limited by the Nyquist frequency. Returns an empty array if no cycle is found.
    """
    x = as_gaw(gaw)
    b = cycle_boundaries(x, fps)
    seg, m = _whole_cycle_segment(x, b, even=False)
    if m == 0:
        return np.zeros(0)
    spec = np.fft.rfft(seg - seg.mean())
    kmax = min(n_harmonics, (spec.size - 1) // m)
    return 2.0 * np.abs(spec[m * np.arange(1, kmax + 1)]) / seg.size


def harmonic_richness_factor(gaw, fps, n_harmonics: int = 10) -> float:
    """Harmonic richness factor HRF = 10 log10(sum_{k>=2} H_k^2 / H_1^2) in dB.

    Source: Childers & Lee (1991), J. Acoust. Soc. Am. 90:2394-2410 (there on the
    glottal flow spectrum). ``H_k`` from :func:`harmonic_amplitudes`. A pure
    sinusoid gives ``-inf``.
    """
    h = harmonic_amplitudes(gaw, fps, n_harmonics)
    if h.size < 2 or h[0] <= 0:
        return float("nan")
    with np.errstate(divide="ignore"):
        return float(10.0 * np.log10(np.sum(h[1:] ** 2) / h[0] ** 2))


def jitter(gaw, fps) -> float:
    """Local period perturbation: mean |T_k - T_{k+1}| / mean T (dimensionless).

    Source: the "jitter (local)" definition of Boersma & Weenink, Praat manual,
    and Lieberman (1963), J. Acoust. Soc. Am. 35:344-353; periods are the
    minimum-to-minimum cycle lengths (sample resolution 1/fps).
    """
    t = cycle_table(gaw, fps)
    p = t["period"]
    if p.size < 2:
        return float("nan")
    return float(np.mean(np.abs(np.diff(p))) / np.mean(p))


def shimmer(gaw, fps) -> float:
    """Local amplitude perturbation: mean |a_k - a_{k+1}| / mean a (dimensionless).

    ``a_k = A_max - A_min`` of cycle k. Source: "shimmer (local)" of the Praat
    manual (Boersma & Weenink); amplitude perturbation of GAWs as in Patel et al.
    (2014).
    """
    t = cycle_table(gaw, fps)
    a = t["a_max"] - t["a_min"]
    if a.size < 2:
        return float("nan")
    return float(np.mean(np.abs(np.diff(a))) / np.mean(a))


def subharmonic_to_harmonic_ratio(gaw, fps, n_harmonics: int = 10) -> float:
    """Subharmonic-to-harmonic ratio SHR = sum_k S_{k-1/2} / sum_k H_k (dimensionless).

    ``H_k`` is the amplitude at ``k f0`` and ``S_{k-1/2}`` at ``(k - 1/2) f0``,
    k = 1..K, measured over an even number of whole cycles so both fall on DFT
    bins. 0 for a strictly periodic GAW; period doubling (alternating cycles)
    raises it. Source: Sun (2002), Proc. IEEE ICASSP, "Pitch determination and
    voice quality analysis using subharmonic-to-harmonic ratio" (there on a
    log spectrum; here on linear amplitudes).
    """
    x = as_gaw(gaw)
    b = cycle_boundaries(x, fps)
    seg, m = _whole_cycle_segment(x, b, even=True)
    if m == 0:
        return float("nan")
    spec = np.abs(np.fft.rfft(seg - seg.mean()))
    kmax = min(n_harmonics, (spec.size - 1) // m)
    k = np.arange(1, kmax + 1)
    harm = spec[m * k].sum()
    sub = spec[m * k - m // 2].sum()
    return float(sub / harm) if harm > 0 else float("nan")


def gaw_measures(gaw, fps, level: float = DEFAULT_LEVEL, n_harmonics: int = 10) -> dict[str, float]:
    """All GAW measures of this module in one dictionary.

    Parameters
    ----------
    gaw : array_like, shape (n,)
        GAW in mm^2.
    fps : float
        Frame rate (Hz).
    level : float
        Open-phase threshold (fraction of peak-to-peak amplitude).
    n_harmonics : int
        Harmonics used by HRF and SHR.

    Returns
    -------
    dict
        ``f0_hz``, ``n_cycles``, ``period_s``, ``min_area_mm2``, ``max_area_mm2``,
        ``amplitude_mm2`` (mean peak-to-peak), ``open_quotient``, ``speed_quotient``,
        ``closing_quotient``, ``amplitude_quotient_s``, ``naq``, ``glottal_gap_index``,
        ``hrf_db``, ``jitter``, ``shimmer``, ``shr``. Values are ``nan`` when the
        GAW has fewer than two cycles.
    """
    x = as_gaw(gaw)
    if not (fps > 0):
        raise ValueError(f"fps must be > 0, got {fps}")
    f0 = estimate_f0(x, fps)
    t = cycle_table(x, fps, level)
    per = t["period"]
    ok_cl = t["t_closing"] > 0
    ok_d = t["dmin"] < 0
    amp = t["a_max"] - t["a_min"]
    return {
        "f0_hz": f0,
        "n_cycles": int(per.size),
        "period_s": _mean(per),
        "min_area_mm2": float(x.min()) if x.size else float("nan"),
        "max_area_mm2": float(x.max()) if x.size else float("nan"),
        "amplitude_mm2": _mean(amp),
        "open_quotient": _mean(t["t_open"] / per) if per.size else float("nan"),
        "speed_quotient": _mean(t["t_opening"][ok_cl] / t["t_closing"][ok_cl]),
        "closing_quotient": _mean(t["t_closing"] / per) if per.size else float("nan"),
        "amplitude_quotient_s": _mean(amp[ok_d] / -t["dmin"][ok_d]),
        "naq": _mean(amp[ok_d] / -t["dmin"][ok_d] / per[ok_d]),
        "glottal_gap_index": _mean(t["a_min"][t["a_max"] > 0] / t["a_max"][t["a_max"] > 0]),
        "hrf_db": harmonic_richness_factor(x, fps, n_harmonics),
        "jitter": float(np.mean(np.abs(np.diff(per))) / np.mean(per)) if per.size > 1 else float("nan"),
        "shimmer": float(np.mean(np.abs(np.diff(amp))) / np.mean(amp)) if amp.size > 1 else float("nan"),
        "shr": subharmonic_to_harmonic_ratio(x, fps, n_harmonics),
    }
