"""Figures of a posterior, in the manner of Hadwin et al. (2019), Figs 4-8: the recording against the model's
90 % band and the wider band of replicated recordings (model plus observation noise), zoomed on the last
cycles with the residual below so that the bands are visible; an ArviZ pair plot in paper units with the
mean, the 90 % interval and, when known, the truth; flow and contact pressure in readable units.

Every function returns PNG bytes and is deterministic (fixed seeds, no timestamps in the file)."""

from __future__ import annotations

import io

import numpy as np

from vfcore.params import PARAM_UNITS

#: Posterior-predictive quantities shown, with their label and the factor from SI to the unit shown.
PREDICTIVE = {
    "mean_flow": ("mean flow rate", "ml/s", 1e6),
    "contact_impulse": ("contact impulse per cycle", "mN s/m", 1e3),
    "contact_pressure_in_contact": ("contact pressure while in contact", "kPa", 1e-3),
    "mean_contact": ("mean nodal contact pressure*", "kPa", 1e-3),
    "max_contact": ("peak nodal contact pressure*", "kPa", 1e-3),
}
#: Replicated recordings drawn per posterior draw for the band that includes noise.
N_REPLICATES = 20
LEGEND = dict(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _png(fig, dpi: int = 110) -> bytes:
    plt = _plt()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": None}, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def _finite_rows(g) -> np.ndarray | None:
    if g is None:
        return None
    g = np.asarray(g, dtype=float)
    return g[np.all(np.isfinite(g), axis=1)]


def replicate_band(gaw: np.ndarray, noise_sd: float, seed: int = 0) -> np.ndarray:
    """5/50/95 % of replicated recordings: each predicted GAW (rows) plus ``N_REPLICATES`` draws of white noise
    of sd ``noise_sd`` (mm^2). Shape (3, n_frames)."""
    rng = np.random.default_rng(seed)
    reps = gaw[None, :, :] + rng.normal(0.0, noise_sd, size=(N_REPLICATES, *gaw.shape))
    return np.quantile(reps.reshape(-1, gaw.shape[1]), [0.05, 0.5, 0.95], axis=0)


def fig_gaw_fit(post, bands, noise_sd: float | None = None, cycles: int = 4, pred=None) -> bytes:
    """Top: the last ``cycles`` cycles of the recording (dots), the model's 90 % posterior band and median, and
    the 90 % band of replicated recordings; bottom: the residual (recording - median) against both bands
    centred on zero. ``bands``: (3, n) model quantiles; ``noise_sd``: mm^2, None to leave the noise band out;
    ``pred``: the resampled predictive the bands came from (default ``post.resampled_predictive()``; a job with an
    unknown area scale passes its draws scaled by ``k``, what the camera records)."""
    plt = _plt()
    fig, (ax, axr) = plt.subplots(2, 1, figsize=(9, 5.2), sharex=True, gridspec_kw={"height_ratios": [2.2, 1]})
    if post.obs_gaw is None:
        ax.text(0.5, 0.5, "no recording stored", ha="center", transform=ax.transAxes)
        return _png(fig)
    obs = np.asarray(post.obs_gaw, dtype=float)
    fps = float(post.fps or 1.0)
    t = np.arange(obs.size) / fps * 1e3
    n = obs.size if bands is None else min(obs.size, bands.shape[1])
    lo = 0
    try:
        from vfcore.measures import estimate_f0

        f0 = float(estimate_f0(obs, fps))
        if np.isfinite(f0) and f0 > 0:
            lo = max(0, n - int(round(cycles * fps / f0)))
    except Exception:  # noqa: BLE001 - without an f0 the whole recording is shown
        lo = 0
    sl = slice(lo, n)
    rep = None
    pred = post.resampled_predictive() if pred is None else pred
    g = _finite_rows(None if pred is None else pred.gaw)
    if noise_sd and g is not None and g.shape[0]:
        rep = replicate_band(g[:, :n], float(noise_sd))
    if rep is not None:
        ax.fill_between(
            t[sl],
            rep[0, sl],
            rep[2, sl],
            color="C0",
            alpha=0.18,
            lw=0,
            label=f"90 % of replicated recordings (noise sd {noise_sd:.2g} mm$^2$)",
        )
    if bands is not None:
        ax.fill_between(t[sl], bands[0, sl], bands[2, sl], color="C1", alpha=0.55, lw=0, label="90 % model band")
        ax.plot(t[sl], bands[1, sl], color="C1", lw=1.4, label="posterior median")
    ax.plot(t[sl], obs[sl], "k.", ms=3, label="recording")
    ax.set_ylabel("glottal area (mm$^2$)")
    ax.set_title(
        f"GAW fit: last {cycles} cycles ({post.method}, ESS {post.ess:.0f})"
        if lo
        else f"GAW fit ({post.method}, ESS {post.ess:.0f})"
    )
    ax.legend(**LEGEND)
    if bands is not None:
        res = obs[sl] - bands[1, sl]
        if rep is not None:
            axr.fill_between(t[sl], rep[0, sl] - bands[1, sl], rep[2, sl] - bands[1, sl], color="C0", alpha=0.18, lw=0)
        axr.fill_between(t[sl], bands[0, sl] - bands[1, sl], bands[2, sl] - bands[1, sl], color="C1", alpha=0.55, lw=0)
        axr.axhline(0.0, color="C1", lw=1)
        axr.plot(t[sl], res, "k.", ms=3)
        axr.set_ylabel("residual (mm$^2$)")
    axr.set_xlabel("time (ms)")
    fig.align_ylabels((ax, axr))
    return _png(fig)


def _label(name: str) -> str:
    return f"{name} ({PARAM_UNITS.get(name, '')})"


def fig_corner(post, bands=None, truth: dict | None = None) -> bytes:
    """ArviZ pair plot of the resampled ensemble (KDE contours, marginals) in paper units; dashed lines: the
    90 % interval, solid: the posterior mean; red: ``truth`` ({name: value}, paper units) when known."""
    import arviz as az
    from matplotlib.ticker import MaxNLocator

    plt = _plt()
    x = np.asarray(post.resampled_samples, dtype=float)
    names = list(post.names)
    d = len(names)
    truth = {k: float(v) for k, v in (truth or {}).items() if k in names}
    data = az.from_dict(posterior={n: x[None, :, j] for j, n in enumerate(names)})
    size = max(4.0, 2.2 * d)
    if d == 1:
        fig, ax = plt.subplots(figsize=(5, 3.5))
        az.plot_posterior(
            data, var_names=names, hdi_prob=0.9, point_estimate="mean", ax=ax, ref_val=truth.get(names[0])
        )
        ax.set_xlabel(_label(names[0]))
        return _png(fig)
    fig, axes = plt.subplots(d, d, figsize=(size, size), squeeze=False)
    # a degenerate ensemble (a few distinct draws, or a parameter without spread) has no density to
    # smooth: scatter and histograms only
    smooth = np.unique(x, axis=0).shape[0] >= 5 and bool(np.all(np.ptp(x, axis=0) > 0))
    axes = az.plot_pair(
        data,
        var_names=names,
        kind=["scatter", "kde"] if smooth else "scatter",
        marginals=True,
        point_estimate="mean",
        marginal_kwargs=None if smooth else {"kind": "hist"},
        ax=axes,
        reference_values=truth if truth and set(truth) >= set(names) else None,
        textsize=9,
        scatter_kwargs={"color": "0.55", "alpha": 0.35, "s": 5},
        kde_kwargs={
            "fill_last": False,
            "contour_kwargs": {"colors": "C0", "linewidths": 1},
            "contourf_kwargs": {"alpha": 0},
        },
        point_estimate_marker_kwargs={"color": "k", "s": 20},
        reference_values_kwargs={"color": "C3", "marker": "x", "markersize": 8},
    )
    axes = np.atleast_2d(axes)
    q05, q95 = np.quantile(x, 0.05, axis=0), np.quantile(x, 0.95, axis=0)
    for i in range(d):
        for j in range(d):
            a = axes[i, j]
            if a is None or not a.get_visible():
                continue
            a.xaxis.set_major_locator(MaxNLocator(3))
            if i != j:
                a.yaxis.set_major_locator(MaxNLocator(3))
            a.tick_params(labelsize=8)
            # with two parameters ArviZ lays the plot out as a joint plot: the second marginal lies on its side
            rotated = d == 2 and i == j == 1
            if i == j:
                line = a.axhline if rotated else a.axvline
                for q in (q05[i], q95[i]):
                    line(q, color="k", ls="--", lw=0.8)
                if names[i] in truth:
                    line(truth[names[i]], color="C3", lw=1.2)
            a.set_xlabel(_label(names[j]) if i == d - 1 and not rotated else "", fontsize=9)
            a.set_ylabel(_label(names[i]) if (j == 0 and i > 0) else "", fontsize=9)
    fig.suptitle(
        "posterior (resampled ensemble); dashed: 90 % interval" + ("; red: truth" if truth else ""), fontsize=10
    )
    return _png(fig, dpi=100)


def fig_contact(post, bands=None) -> bytes:
    """Posterior predictive histograms of flow and contact pressure with mean and 90 % interval; * marks the
    nodal peaks that depend on the mesh and time step (:ref:`model-contact`)."""
    from matplotlib.ticker import MaxNLocator

    plt = _plt()
    pred = post.resampled_predictive()
    shown = [(k, v) for k, v in PREDICTIVE.items() if pred is not None and getattr(pred, k, None) is not None]
    shown = shown or list(PREDICTIVE.items())[:1]
    ncol = min(3, len(shown))
    nrow = -(-len(shown) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.6 * ncol, 2.9 * nrow), squeeze=False)
    for ax, (name, (label, unit, k)) in zip(axes.flat, shown):
        a = None if pred is None else getattr(pred, name, None)
        a = None if a is None else np.asarray(a, dtype=float)
        a = None if a is None else a[np.isfinite(a)] * k
        if a is not None and a.size:
            ax.hist(a, bins=30, color="C2", alpha=0.8)
            q = np.quantile(a, [0.05, 0.95])
            for v in q:
                ax.axvline(v, color="k", ls="--", lw=0.8)
            ax.axvline(a.mean(), color="k", lw=1.2)
        else:
            ax.text(0.5, 0.5, "not available", ha="center", transform=ax.transAxes)
        ax.set_xlabel(f"{label} ({unit})", fontsize=9)
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.tick_params(labelsize=8)
        ax.set_yticks([])
    for ax in list(axes.flat)[len(shown) :]:
        ax.set_visible(False)
    fig.suptitle(
        "posterior predictive flow and contact (solid: mean, dashed: 90 % interval; * mesh-dependent)", fontsize=10
    )
    fig.tight_layout()
    return _png(fig)
