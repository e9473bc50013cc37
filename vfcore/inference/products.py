"""Posterior products: predictive GAW bands, flow and contact-pressure tables, t-tests, figures.

* Posterior-predictive GAW (Hadwin et al. 2019, Figs. 4-6): the aligned simulated GAW of every
  draw of the resampled ensemble; pointwise mean and central quantile bands. ``noise=True``
  adds the measurement noise N(0, sigma_e^2) to the band (prediction of a new recording).
* Flow rate Q (Table 6) and mean / maximum contact pressure (Table 7): mean +- sd over the
  resampled ensemble of each draw's cycle-averaged value.
* Pairwise comparison of two fitted data sets (Section 5.2): Welch's two-sample t-test
  (``scipy.stats.ttest_ind(equal_var=False)``) on the two resampled ensembles per parameter.
  With posterior samples the p-value shrinks as the ensemble grows, so the standardised
  difference ``(m_a - m_b) / sqrt(sd_a^2 + sd_b^2)`` is reported beside it.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy import stats

from ..params import PARAM_UNITS
from .posterior import Posterior


def _require_predictive(post: Posterior):
    rp = post.resampled_predictive()
    if rp is None or rp.gaw is None:
        raise ValueError("posterior carries no model predictions (it was not fitted with the FE model)")
    return rp


def predictive_bands(
    post: Posterior, level: float = 0.9, sigma_e: float | None = None, seed: int = 0
) -> dict[str, np.ndarray]:
    """Pointwise posterior-predictive summary of the aligned GAW.

    Returns ``t`` (s), ``mean``, ``median``, ``lo``, ``hi`` (central ``level`` band), ``sd`` and
    ``obs`` (when stored), all (n_compare,). With ``sigma_e`` the band includes observation
    noise (deterministic in ``seed``).
    """
    rp = _require_predictive(post)
    g = rp.gaw[rp.ok].astype(float)
    if g.shape[0] == 0:
        raise ValueError("no successful simulation in the resampled ensemble")
    if sigma_e is not None:
        g = g + sigma_e * np.random.default_rng(seed).standard_normal(g.shape)
    a = 0.5 * (1.0 - level)
    lo, med, hi = np.quantile(g, [a, 0.5, 1.0 - a], axis=0)
    fps = post.fps or 1.0
    out = {
        "t": np.arange(g.shape[1]) / fps,
        "mean": g.mean(axis=0),
        "sd": g.std(axis=0, ddof=1) if g.shape[0] > 1 else np.zeros(g.shape[1]),
        "median": med,
        "lo": lo,
        "hi": hi,
    }
    if post.obs_gaw is not None:
        out["obs"] = np.asarray(post.obs_gaw, dtype=float)[: g.shape[1]]
    return out


def flow_contact_table(post: Posterior) -> list[dict]:
    """Table 6/7 analogue, mean +- sd over the resampled ensemble: mean flow (mL/s), contact impulse
    per cycle (mN s/m) and pressure in contact (Pa), which converge with the time step and mesh, and
    the paper's mean and maximum of the nodal peak contact pressure (Pa), which do not (:ref:`model`,
    "Contact"; labelled so). A quantity the ensemble does not carry is omitted."""
    rp = _require_predictive(post)
    rows = []
    for key, label, unit, factor in (
        ("mean_flow", "flow rate Q", "mL/s", 1e6),
        ("contact_impulse", "contact impulse per cycle", "mN s/m", 1e3),
        ("contact_pressure_in_contact", "pressure in contact", "Pa", 1.0),
        ("mean_contact", "mean nodal peak contact pressure (not converged)", "Pa", 1.0),
        ("max_contact", "max nodal contact pressure (not converged)", "Pa", 1.0),
    ):
        if getattr(rp, key) is None:
            continue
        v = np.asarray(getattr(rp, key), dtype=float)[rp.ok] * factor
        v = v[np.isfinite(v)]
        m = float(v.mean()) if v.size else math.nan
        s = float(v.std(ddof=1)) if v.size > 1 else math.nan
        rows.append(
            {
                "quantity": label,
                "unit": unit,
                "mean": m,
                "sd": s,
                "pct": 100.0 * s / abs(m) if m else math.nan,
                "n": int(v.size),
            }
        )
    return rows


def compare(post_a: Posterior, post_b: Posterior, names=None, n: int | None = None) -> list[dict]:
    """Welch t-test per parameter between two posteriors' resampled ensembles (Section 5.2).

    ``names`` defaults to the parameters both estimated (including x0 and p_sub when
    estimated). ``n`` optionally caps the number of draws used from each ensemble.
    """
    common = [x for x in post_a.names if x in post_b.names] if names is None else list(names)
    if not common:
        raise ValueError("the two posteriors share no estimated parameter")
    ra, rb = post_a.resampled_samples, post_b.resampled_samples
    if n is not None:
        ra, rb = ra[:n], rb[:n]
    rows = []
    for name in common:
        if name not in post_a.names or name not in post_b.names:
            raise ValueError(f"parameter {name!r} is not estimated in both posteriors")
        xa = ra[:, post_a.names.index(name)]
        xb = rb[:, post_b.names.index(name)]
        t = stats.ttest_ind(xa, xb, equal_var=False)
        ma, mb, sa, sb = xa.mean(), xb.mean(), xa.std(ddof=1), xb.std(ddof=1)
        rows.append(
            {
                "name": name,
                "unit": PARAM_UNITS.get(name, ""),
                "mean_a": float(ma),
                "sd_a": float(sa),
                "mean_b": float(mb),
                "sd_b": float(sb),
                "t": float(t.statistic),
                "p": float(t.pvalue),
                "df": float(getattr(t, "df", math.nan)),
                "standardized_difference": float((ma - mb) / math.hypot(sa, sb)) if (sa or sb) else math.nan,
            }
        )
    return rows


# ---------------------------------------------------------------------------- figures
def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def plot_predictive(
    post: Posterior, path, level: float = 0.9, sigma_e: float | None = None, title: str | None = None
) -> Path:
    """Observed GAW with the posterior-predictive mean and band (like Figs. 4-6)."""
    plt = _plt()
    b = predictive_bands(post, level=level, sigma_e=sigma_e)
    fig, ax = plt.subplots(figsize=(7, 3.2))
    t_ms = 1e3 * b["t"]
    ax.fill_between(t_ms, b["lo"], b["hi"], color="C0", alpha=0.3, label=f"{int(100 * level)}% band")
    ax.plot(t_ms, b["mean"], color="C0", lw=1.5, label="posterior-predictive mean")
    if "obs" in b:
        ax.plot(t_ms, b["obs"], "k.", ms=3, label="observed")
    ax.set_xlabel("time (ms)")
    ax.set_ylabel("glottal area (mm$^2$)")
    ax.legend(loc="upper right", fontsize=8)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_marginals(post: Posterior, path, truth: dict | None = None, bins: int = 30) -> Path:
    """Histogram of each parameter's resampled ensemble, with the truth when known."""
    plt = _plt()
    d = post.ndim
    fig, axes = plt.subplots(1, d, figsize=(2.4 * d, 2.4), squeeze=False)
    rs = post.resampled_samples
    for j, name in enumerate(post.names):
        ax = axes[0, j]
        ax.hist(rs[:, j], bins=bins, color="C0", alpha=0.7)
        ax.axvline(post.mean[j], color="C0")
        if truth and name in truth:
            ax.axvline(truth[name], color="k", ls="--")
        ax.set_xlabel(f"{name} ({PARAM_UNITS.get(name, '')})")
        ax.set_yticks([])
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
