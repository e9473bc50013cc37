"""Sensitivity studies (Hadwin et al. 2019, Figs. 7 and 8), each returning a table and a figure.

* ``ensemble_size_study``: estimate error and uncertainty versus the number of importance
  draws (Fig. 7). Prior draws are i.i.d., so a random subset of size n of a large IS ensemble
  *is* an n-draw IS run; subsets are re-weighted and repeated to show the Monte Carlo spread.
* ``numerics_study``: estimates versus time step and mesh density (Fig. 8): the same
  inference rerun for each ``SimConfig``.
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from ..config import MESHES, SimConfig
from ..params import PARAM_UNITS
from .diagnostics import ess as _ess
from .diagnostics import normalize_log_weights
from .posterior import Posterior
from .problem import Problem


def write_table(rows: list[dict], path) -> Path:
    """Write a list of dicts as CSV (columns from the first row)."""
    path = Path(path)
    if not rows:
        path.write_text("")
        return path
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return path


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def ensemble_size_study(
    post: Posterior,
    sizes,
    *,
    truth: Mapping[str, float] | None = None,
    n_repeats: int = 5,
    seed: int = 0,
    figure_path=None,
) -> list[dict]:
    """Error and uncertainty of the IS estimate versus ensemble size (Fig. 7).

    ``post`` must be an importance-sampling posterior (its samples are prior draws and its
    log-weights the log-likelihoods up to a constant). For each size n, ``n_repeats`` random
    subsets are re-weighted. The error is measured against ``truth`` when given, else against
    the full-ensemble estimate. Rows: n, name, mean, sd (posterior sd, averaged over repeats),
    error (mean |estimate - reference|), spread (sd of the estimate over repeats), ess.
    """
    if post.method != "importance":
        raise ValueError("ensemble_size_study needs an importance-sampling posterior (i.i.d. prior draws)")
    N = post.samples.shape[0]
    sizes = sorted({int(s) for s in sizes if 1 < int(s) <= N})
    if not sizes:
        raise ValueError(f"no usable ensemble size (need 1 < n <= {N})")
    ref = np.array([truth[n] for n in post.names]) if truth is not None else post.mean
    rng = np.random.default_rng(seed)
    rows = []
    for n in sizes:
        reps = 1 if n == N else int(n_repeats)
        est, sds, esss = [], [], []
        for _ in range(reps):
            idx = np.arange(N) if n == N else rng.choice(N, size=n, replace=False)
            lw = post.log_weights[idx]
            if not np.any(np.isfinite(lw)):
                continue
            w = np.exp(normalize_log_weights(lw))
            x = post.samples[idx]
            m = w @ x
            est.append(m)
            sds.append(np.sqrt(np.clip(w @ (x - m) ** 2, 0, None)))
            esss.append(_ess(lw))
        if not est:
            continue
        est, sds = np.array(est), np.array(sds)
        for j, name in enumerate(post.names):
            rows.append(
                {
                    "n": n,
                    "name": name,
                    "unit": PARAM_UNITS.get(name, ""),
                    "mean": float(est[:, j].mean()),
                    "sd": float(sds[:, j].mean()),
                    "error": float(np.mean(np.abs(est[:, j] - ref[j]))),
                    "spread": float(est[:, j].std(ddof=1)) if est.shape[0] > 1 else 0.0,
                    "ess": float(np.mean(esss)),
                }
            )
    if figure_path is not None:
        _plot_vs(rows, post.names, "n", figure_path, xlabel="ensemble size N", logx=True, truth=ref)
    return rows


def dt_mesh_configs(base: SimConfig, dts=(1e-4, 5e-5, 2.5e-5), meshes=MESHES) -> dict[str, SimConfig]:
    """Configurations for the Fig. 8 study: each dt at the base mesh, each mesh at the base dt."""
    out = {}
    for dt in dts:
        out[f"dt={dt:g}"] = base.replace(dt=dt)
    for m in meshes:
        out[f"mesh={m}"] = base.replace(mesh=m)
    return out


def numerics_study(
    problem: Problem,
    configs: Mapping[str, SimConfig],
    sampler: Callable[[Problem], Posterior],
    *,
    truth: Mapping[str, float] | None = None,
    figure_path=None,
) -> list[dict]:
    """Rerun the inference for each numerical configuration (Fig. 8).

    ``sampler(problem) -> Posterior`` (e.g. ``lambda p: smc(p, seed=1, map=pool.map)``).
    Rows: config, name, mean, sd, error (|mean - truth| when given), n_simulations.
    """
    from dataclasses import replace

    rows = []
    names = problem.prior.names
    for label, cfg in configs.items():
        p = replace(problem, config=cfg)
        post = sampler(p)
        for j, name in enumerate(names):
            rows.append(
                {
                    "config": label,
                    "name": name,
                    "unit": PARAM_UNITS.get(name, ""),
                    "mean": float(post.mean[j]),
                    "sd": float(post.sd[j]),
                    "error": float(abs(post.mean[j] - truth[name])) if truth and name in truth else float("nan"),
                    "n_simulations": post.n_simulations,
                    "n_failed": post.n_failed,
                }
            )
    if figure_path is not None:
        _plot_vs(
            rows,
            names,
            "config",
            figure_path,
            xlabel="numerical configuration",
            truth=np.array([truth[n] for n in names]) if truth else None,
        )
    return rows


def _plot_vs(rows, names, key, path, *, xlabel, logx=False, truth=None) -> Path:
    plt = _plt()
    d = len(names)
    fig, axes = plt.subplots(d, 1, figsize=(6, 1.9 * d), squeeze=False, sharex=True)
    for j, name in enumerate(names):
        rr = [r for r in rows if r["name"] == name]
        xs = [r[key] for r in rr]
        pos = np.arange(len(xs)) if key == "config" else np.array(xs, dtype=float)
        ax = axes[j, 0]
        ax.errorbar(pos, [r["mean"] for r in rr], yerr=[r["sd"] for r in rr], fmt="o-", ms=3, capsize=2)
        if truth is not None:
            ax.axhline(truth[j], color="k", ls="--", lw=0.8)
        ax.set_ylabel(f"{name}\n({PARAM_UNITS.get(name, '')})", fontsize=8)
        if logx:
            ax.set_xscale("log")
        if key == "config":
            ax.set_xticks(pos)
            ax.set_xticklabels(xs, rotation=30, fontsize=7)
    axes[-1, 0].set_xlabel(xlabel)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
