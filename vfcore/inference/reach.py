"""The model's reach: what a forward model and a prior can produce, checked against a recording before a fit.

A *reach ensemble* is a prior-predictive ensemble for one simulation configuration and one prior: ``N``
independent draws from the prior, simulated in lock-step (:func:`vfcore.batch.simulate_many`), and the GAW
measures of each (:mod:`vfcore.measures`: f0, peak area, open / speed / closing quotients) with whether the
draw phonates. :func:`check_reach` compares the same measures of a recording with the ensemble, before any
sampling, and says whether the recording lies inside, at the margin of, or outside what the model and prior
reach, with the numbers and what would help.

Definitions (:ref:`inference`, "The model's reach"):

* a draw *phonates* when its simulation succeeds and its GAW (after the discarded transient, at
  ``REACH_FPS``) has at least two cycles, a mean peak-to-peak amplitude of at least
  ``PHONATION_MIN_AMPLITUDE`` mm^2, does not decay (the last three cycles' amplitude is at least
  ``SUSTAIN_RATIO`` of the first three's), and its f0 (autocorrelation, :func:`vfcore.measures.estimate_f0`)
  agrees within ``F0_AGREEMENT`` with the simulation's own cycle rate (``SimResult.f0``: mean-crossing
  cycles, chatter shorter than 1 ms dropped). The last rule excludes contact chatter: small-amplitude
  400-500 Hz flicker of a fold that is otherwise at rest, which autocorrelation alone reads as a pitch;
* per measure, over the phonating draws: 5 / 50 / 95 % quantiles, min and max. A recording's value is
  *inside* within the 5-95 % range, *marginal* beyond it but within [min, max] (fewer than 5 % of the
  phonating draws reach it), *outside* beyond every draw;
* the verdict is *outside* when f0 or the peak area is outside (no draw reaches the recording's frequency
  or size, so a fit can only pile on the prior's bounds); a quotient outside, or no draw near the
  recording in f0 and peak area together (``NEAR_F0`` and ``NEAR_AREA``), makes it at most *marginal*;
* with an unknown area scale ``k`` on ``[k_lo, k_hi]`` (an uncalibrated video, ``area_scale``) the recording's
  peak area ``A`` stands for a true peak area anywhere in ``[A / k_hi, A / k_lo]``; the area's verdict is then
  that of the interval's nearest point (it is outside only when the whole interval is), and "near" in area
  means near some point of it. The other measures do not depend on the scale.

Ensembles are keyed by :func:`reach_key`, a hash of the configuration's physics and numerics (everything in
``SimConfig`` but the camera rate and trajectory output) and of the prior (bounds and fixed values). They are
looked up in the user cache (``VFINFER_CACHE_DIR``, else ``$XDG_CACHE_HOME/vfinfer``, else
``~/.cache/vfinfer``; subfolder ``reach``) and then among the ensembles shipped in ``vfcore/data``
(``reach_<key>.csv``, made by ``scripts/make_reach_ensembles.py``). A prior without its own ensemble may be
checked against an ensemble of a *wider* prior for the same configuration (:func:`find_ensemble`): its
reach is contained in the wider one's, so "outside" carries over and nothing else does.

This module finds ensembles and checks recordings end to end; the ensemble itself (draws, measures, key, CSV)
is :mod:`.reach_ensemble`, the comparison and its message :mod:`.reach_verdict`. Their public names are
re-exported here, the one place callers import them from.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

from ..config import SimConfig
from ..params import PARAM_NAMES
from .prior import Prior
from .reach_ensemble import (
    DEFAULT_N,
    DEFAULT_SEED,
    F0_AGREEMENT,
    MEASURES,
    PHONATION_MIN_AMPLITUDE,
    QUANTILES,
    REACH_FPS,
    REACH_VERSION,
    SUSTAIN_RATIO,
    ReachEnsemble,
    build_ensemble,
    config_hash,
    config_key_dict,
    draw_measures,
    reach_key,
)
from .reach_verdict import (
    HARD_MEASURES,
    NEAR_AREA,
    NEAR_F0,
    ReachVerdict,
    check_reach,
    format_table,
    recording_measures,
)

SHIPPED_DIR = Path(__file__).resolve().parent.parent / "data"


def cache_dir() -> Path:
    """Folder of the user's reach ensembles: ``$VFINFER_CACHE_DIR/reach`` or the XDG cache's ``vfinfer/reach``."""
    base = os.environ.get("VFINFER_CACHE_DIR")
    if not base:
        base = os.path.join(
            os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "vfinfer"
        )
    return Path(base) / "reach"


def ensemble_path(key: str, folder: Path | None = None) -> Path:
    return Path(folder if folder is not None else cache_dir()) / f"reach_{key}.csv"


def save_cached(ens: ReachEnsemble, folder: Path | None = None) -> Path:
    return ens.save(ensemble_path(ens.key, folder))


_LOADED: dict[tuple[str, int, int], ReachEnsemble] = {}


def _load(path: Path) -> ReachEnsemble:
    """:meth:`ReachEnsemble.load`, memoised on the file's path, size and modification time (a service checks
    every submission against the same few files)."""
    st = os.stat(path)
    k = (str(path), st.st_mtime_ns, st.st_size)
    if k not in _LOADED:
        if len(_LOADED) > 32:
            _LOADED.clear()
        _LOADED[k] = ReachEnsemble.load(path)
    return _LOADED[k]


def _candidates() -> list[Path]:
    out = []
    for d in (cache_dir(), SHIPPED_DIR):
        if d.is_dir():
            out += sorted(d.glob("reach_*.csv"))
    return out


def _box(prior_dict: Mapping) -> dict[str, tuple[float, float]]:
    b = {n: (float(lo), float(hi)) for n, (lo, hi) in prior_dict["bounds"].items()}
    b.update({n: (float(v), float(v)) for n, v in prior_dict.get("fixed", {}).items()})
    return b


def _contains(wide: Mapping, narrow: Mapping) -> bool:
    """Whether the prior box ``wide`` contains ``narrow`` (fixed values as degenerate intervals); a parameter
    that neither estimates nor fixes is at its Table 3 value."""
    from ..params import TABLE3

    w, s = _box(wide), _box(narrow)
    for name in PARAM_NAMES:
        t3 = float(getattr(TABLE3, name))
        wl, wh = w.get(name, (t3, t3))
        sl, sh = s.get(name, (t3, t3))
        if not (wl <= sl and sh <= wh):
            return False
    return True


def find_ensemble(config: SimConfig, prior: Prior) -> tuple[ReachEnsemble | None, bool]:
    """The ensemble for ``config`` and ``prior``: ``(ensemble, exact)``. The user cache comes before the
    shipped ones. Without an exact one, an ensemble of the same configuration whose prior box contains
    this prior's (``exact`` False: only its "outside" verdicts carry over); ``(None, False)`` when neither."""
    key = reach_key(config, prior)
    for d in (cache_dir(), SHIPPED_DIR):
        p = ensemble_path(key, d)
        if p.is_file():
            try:
                return _load(p), True
            except (ValueError, OSError, KeyError, IndexError):
                continue
    want = config_hash(config)
    pd = prior.to_dict()
    best = None
    for p in _candidates():
        try:
            ens = _load(p)
        except (ValueError, OSError, KeyError, IndexError):
            continue
        if config_hash(ens.sim_config()) == want and _contains(ens.prior, pd):
            if best is None or ens.n > best.n:
                best = ens
    return best, False


def origin(ens: ReachEnsemble) -> str:
    """Where ``ens`` came from: "shipped" (``vfcore/data``) or "cached" (the user cache, built earlier)."""
    return "shipped" if Path(ens.source).resolve().parent == SHIPPED_DIR else "cached"


def first_use_prior(prior: Prior, prior_set: Prior) -> Prior:
    """The prior an ensemble built on first use simulates: the named ``prior_set``'s box when it contains
    ``prior``, as a shipped ensemble does (one build then serves every fix and narrowing of the set, checked as
    an ensemble of a wider prior), else ``prior`` itself."""
    return prior_set if _contains(prior_set.to_dict(), prior.to_dict()) else prior


def reach_for(
    gaw, fps: float, config: SimConfig, prior: Prior, area_scale: tuple[float, float] | None = None
) -> ReachVerdict:
    """Find the ensemble for ``config`` and ``prior`` and check the recording ``gaw`` at ``fps`` against it
    (``area_scale``: an unknown area scale's box, :func:`check_reach`)."""
    ens, exact = find_ensemble(config, prior)
    v = check_reach(recording_measures(gaw, fps), ens, exact=exact, area_scale=area_scale)
    if v.verdict == "unchecked":
        v.message += "; " + build_hint(config, prior)
    return v


def build_hint(config: SimConfig, prior: Prior) -> str:
    """The ``vfinfer reach`` command that builds the ensemble for ``config`` and ``prior``."""
    from .prior import PRIOR_SETS

    args = [
        f"--mesh {config.mesh}",
        f"--dt {config.dt:g}",
        f"--duration {config.duration:g}",
        f"--discard {config.discard:g}",
    ]
    if config.element != "p1":
        args.append(f"--element {config.element}")
    if config.contact != "projection":
        args.append(f"--contact {config.contact} --contact-layer-mm {config.contact_layer_mm:g}")
    # the named set the prior differs least from, then the bounds that differ from it
    name_set = min(PRIOR_SETS, key=lambda k: sum(PRIOR_SETS[k].get(n) != b for n, b in prior.bounds.items()))
    if name_set != "paper":
        args.append(f"--prior-set {name_set}")
    for name, (lo, hi) in prior.bounds.items():
        if PRIOR_SETS[name_set].get(name) != (lo, hi):
            args.append(f"--prior {name}={lo:g}:{hi:g}")
    for name, v in prior.fixed.items():
        args.append(f"--fix {name}={v:g}")
    return f"build it with `vfinfer reach {' '.join(args)}` ({DEFAULT_N} simulations, minutes on one core)"


__all__ = [
    "DEFAULT_N",
    "DEFAULT_SEED",
    "F0_AGREEMENT",
    "HARD_MEASURES",
    "MEASURES",
    "NEAR_AREA",
    "NEAR_F0",
    "PHONATION_MIN_AMPLITUDE",
    "QUANTILES",
    "REACH_FPS",
    "REACH_VERSION",
    "SUSTAIN_RATIO",
    "ReachEnsemble",
    "ReachVerdict",
    "build_ensemble",
    "build_hint",
    "cache_dir",
    "check_reach",
    "config_key_dict",
    "draw_measures",
    "ensemble_path",
    "find_ensemble",
    "first_use_prior",
    "format_table",
    "origin",
    "reach_for",
    "reach_key",
    "recording_measures",
    "save_cached",
]
