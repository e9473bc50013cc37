"""The diagnosis figure: the recording with the base and named fits, the residual by cycle phase, and
the GAW measures' posterior-predictive p-values."""

from __future__ import annotations

import math

import numpy as np

from ..inference.problem import Problem
from .locate import PHASES, locate
from .report import DiagnoseReport
from .summary import predicted_gaws

__all__ = ["plot_diagnosis"]


def plot_diagnosis(report: DiagnoseReport, problem: Problem, path, level: float = 0.9):
    """Recording, base and extended fits with their bands, the residual by cycle phase, and the GAW
    measures' posterior-predictive p-values of each fit (the fit summaries' ``pvalues``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    y = problem.obs_compared
    t = np.arange(y.size) / problem.fps * 1e3
    fig, (a1, a2, a3) = plt.subplots(
        3, 1, figsize=(9, 10), constrained_layout=True, gridspec_kw={"height_ratios": [1.1, 1.0, 0.9]}
    )
    a1.plot(t, y, "k.", ms=2.5, label="recording")
    fits = [("base", report.base, "tab:blue")]
    summaries = [report.before]
    if report.winner:
        fits.append((report.winner, report.refits[report.winner], "tab:red"))
        summaries.append(report.after.get(report.winner, {}))
    q = (1 - level) / 2
    for label, post, c in fits:
        g = predicted_gaws(post)
        n = g.shape[1]
        a1.fill_between(t[:n], np.quantile(g, q, axis=0), np.quantile(g, 1 - q, axis=0), color=c, alpha=0.25)
        rms = math.sqrt(float(np.mean((y[:n] - g.mean(axis=0)) ** 2)))
        a1.plot(t[:n], g.mean(axis=0), color=c, lw=1, label=f"{label} fit (RMS {rms:.2f} mm$^2$)")
        loc = locate(y[:n], g, problem.fps)
        where = f"dominant phase {loc.dominant_phase}" if loc.dominant_phase in PHASES else "spread over the cycle"
        a2.plot(loc.fold_phase, loc.fold_mean, color=c, marker="o", ms=3, label=f"{label}: residual, {where}")
    a1.set_xlabel("time (ms)")
    a1.set_ylabel("glottal area (mm$^2$)")
    import textwrap

    a1.set_title("\n".join(textwrap.wrap(report.verdict, 105)), fontsize=10)
    a1.legend(fontsize=8)
    a2.axhline(0, color="grey", lw=0.8)
    a2.set_xlabel("cycle phase (0 = area minimum)")
    a2.set_ylabel("mean residual, recording - fit (mm$^2$)")
    a2.legend(fontsize=8)
    names = list((report.before.get("pvalues") or {}).keys())
    x = np.arange(len(names))
    wd = 0.8 / len(fits)
    for k, ((label, _, c), summ) in enumerate(zip(fits, summaries)):
        pv = summ.get("pvalues") or {}
        # two-sided p of 0 is "below 1/draws": drawn at 1/(2 x 100) so the bar shows
        v = [
            -math.log10(max(float(pv.get(n, math.nan)), 0.005)) if math.isfinite(pv.get(n, math.nan)) else 0.0
            for n in names
        ]
        a3.bar(x + (k - (len(fits) - 1) / 2) * wd, v, wd, color=c, alpha=0.8, label=label)
    a3.axhline(-math.log10(0.05), color="grey", lw=0.8, ls="--", label="p = 0.05")
    a3.set_xticks(
        x,
        [n.replace("_mm2", "").replace("_hz", "").replace("_s", "").replace("_db", "") for n in names],
        rotation=30,
        ha="right",
        fontsize=8,
    )
    a3.set_ylabel("$-\\log_{10}$ p (two-sided)")
    a3.set_title("GAW measures: recording against each fit's replicated recordings", fontsize=9)
    a3.legend(fontsize=8)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
