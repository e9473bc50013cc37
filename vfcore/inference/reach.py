"""The model's reach: what a forward model and a prior can produce, checked against a recording before a fit.

A *reach ensemble* is a prior-predictive ensemble for one simulation configuration and one prior: ``N``
independent draws from the prior, simulated in lock-step (:func:`vfcore.batch.simulate_many`), and the GAW
measures of each (:mod:`vfcore.measures`: f0, peak area, open / speed / closing quotients) with whether the
draw phonates. :func:`check_reach` compares the same measures of a recording with the ensemble, before any
sampling, and says whether the recording lies inside, at the margin of, or outside what the model and prior
reach, with the numbers and what would help.

Definitions (docs/inference.md, "The model's reach"):

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
"""
from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import os
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from ..config import SimConfig
from ..params import PARAM_NAMES
from .prior import Prior

#: Bumped when the ensemble's protocol (measures, phonation rule, CSV layout) changes; part of the key.
REACH_VERSION = 1
#: Camera rate at which the ensemble's GAWs are measured (capped at 1/dt); not part of the key.
REACH_FPS = 4000.0
#: Smallest mean peak-to-peak GAW amplitude (mm^2) that counts as phonation (as ``forward.MIN_CYCLE_AMPLITUDE``).
PHONATION_MIN_AMPLITUDE = 0.05
#: A phonating GAW's last three cycles keep at least this fraction of the first three's amplitude.
SUSTAIN_RATIO = 0.5
#: Largest relative difference between the GAW's autocorrelation f0 and the simulation's cycle rate.
F0_AGREEMENT = 0.10
#: The measures compared: (column, label, unit, format).
MEASURES: tuple[tuple[str, str, str, str], ...] = (
    ("f0_hz", "f0", "Hz", ".0f"),
    ("max_area_mm2", "peak area", "mm^2", ".3g"),
    ("open_quotient", "open quotient", "", ".2f"),
    ("speed_quotient", "speed quotient", "", ".2f"),
    ("closing_quotient", "closing quotient", "", ".2f"),
)
#: Measures whose being outside makes the verdict "outside"; the quotients make it at most "marginal".
HARD_MEASURES = ("f0_hz", "max_area_mm2")
#: A draw is "near" the recording when its f0 is within this relative distance ...
NEAR_F0 = 0.10
#: ... and its peak area within this factor of the recording's.
NEAR_AREA = 1.5
QUANTILES = (0.05, 0.5, 0.95)
#: Draws of a shipped ensemble and of ``vfinfer reach`` unless told otherwise.
DEFAULT_N = 2000
DEFAULT_SEED = 20190613

# early_stop only ends simulations whose response has settled, which changes no ensemble statistic
_KEY_EXCLUDE = ("fps", "keep_trajectories", "early_stop")
_VERDICTS = ("inside", "marginal", "outside")
SHIPPED_DIR = Path(__file__).resolve().parent.parent / "data"


# ------------------------------------------------------------------------------------------- keys
def _canonical(x):
    if isinstance(x, Mapping):
        return {str(k): _canonical(v) for k, v in sorted(x.items())}
    if isinstance(x, (list, tuple)):
        return [_canonical(v) for v in x]
    if isinstance(x, (float, int, np.floating, np.integer)) and not isinstance(x, bool):
        return repr(float(x))          # 1 and 1.0 are one value; repr keeps every digit
    return x


def config_key_dict(config: SimConfig) -> dict:
    """The part of ``config`` a reach ensemble depends on (everything but the camera rate and trajectories)."""
    d = {k: v for k, v in config.as_dict().items() if k not in _KEY_EXCLUDE}
    if d["contact"] == "projection":
        # the layer options do not enter the physics of the rigid projection: its key leaves them out
        del d["contact"], d["contact_layer_mm"]
    return d


def reach_key(config: SimConfig, prior: Prior) -> str:
    """Hex key (16 digits of SHA-256) of the ensemble for ``config`` and ``prior``."""
    blob = json.dumps({"version": REACH_VERSION, "config": _canonical(config_key_dict(config)),
                       "prior": _canonical(prior.to_dict())}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def _config_hash(config: SimConfig) -> str:
    blob = json.dumps({"version": REACH_VERSION, "config": _canonical(config_key_dict(config))}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def cache_dir() -> Path:
    """Folder of the user's reach ensembles: ``$VFINFER_CACHE_DIR/reach`` or the XDG cache's ``vfinfer/reach``."""
    base = os.environ.get("VFINFER_CACHE_DIR")
    if not base:
        base = os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"),
                            "vfinfer")
    return Path(base) / "reach"


# ------------------------------------------------------------------------------------------- ensemble
@dataclass
class ReachEnsemble:
    """A prior-predictive ensemble: per draw the seven parameters, success, phonation and the measures."""

    config: dict                      # config_key_dict of the SimConfig it was simulated with
    prior: dict                       # Prior.to_dict()
    params: np.ndarray                # (N, 7) PARAM_NAMES order, paper units
    ok: np.ndarray                    # (N,) bool: simulation succeeded
    phonates: np.ndarray              # (N,) bool
    measures: dict[str, np.ndarray]   # column -> (N,), nan where undefined
    key: str = ""
    seed: int | None = None
    wall_s: float | None = None
    source: str = ""                  # where it was read from

    def __post_init__(self) -> None:
        if not self.key:
            self.key = reach_key(self.sim_config(), self.prior_obj())

    @property
    def n(self) -> int:
        return int(self.ok.size)

    @property
    def phonating_fraction(self) -> float:
        return float(np.mean(self.phonates)) if self.n else math.nan

    def sim_config(self) -> SimConfig:
        return SimConfig(**{**self.config, "fps": min(REACH_FPS, 1.0 / float(self.config["dt"]))})

    def prior_obj(self) -> Prior:
        return Prior.from_dict(self.prior)

    def stats(self) -> dict[str, dict]:
        """Per measure over the phonating draws: q05, q50, q95, min, max (nan without any)."""
        out = {}
        for col, *_ in MEASURES:
            v = self.measures[col][self.phonates]
            v = v[np.isfinite(v)]
            if v.size:
                q = np.quantile(v, QUANTILES)
                out[col] = {"q05": float(q[0]), "q50": float(q[1]), "q95": float(q[2]),
                            "min": float(v.min()), "max": float(v.max()), "n": int(v.size)}
            else:
                out[col] = {"q05": math.nan, "q50": math.nan, "q95": math.nan, "min": math.nan,
                            "max": math.nan, "n": 0}
        return out

    # -------------------------------------------------------------------------------- CSV
    def to_csv_text(self) -> str:
        buf = io.StringIO()
        meta = {"reach_version": REACH_VERSION, "key": self.key, "config": self.config, "prior": self.prior,
                "n_draws": self.n, "seed": self.seed, "wall_s": self.wall_s, "fps": self.sim_config().fps,
                "phonation_min_amplitude_mm2": PHONATION_MIN_AMPLITUDE}
        buf.write("# vfinfer reach ensemble (vfcore.inference.reach): prior draws simulated and measured\n")
        for k, v in meta.items():
            buf.write(f"# {k}: {json.dumps(v, sort_keys=True)}\n")
        w = csv.writer(buf, lineterminator="\n")
        cols = [col for col, *_ in MEASURES]
        w.writerow([*PARAM_NAMES, "ok", "phonates", *cols])
        for i in range(self.n):
            w.writerow([*(f"{x:.10g}" for x in self.params[i]), int(self.ok[i]), int(self.phonates[i]),
                        *("nan" if not math.isfinite(self.measures[c][i]) else f"{self.measures[c][i]:.6g}"
                          for c in cols)])
        return buf.getvalue()

    def save(self, path: Path) -> Path:
        """Write atomically (a temporary file in the same folder, then ``os.replace``)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(self.to_csv_text())
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)          # mkstemp makes it private; an ensemble is not
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise
        return path

    @classmethod
    def load(cls, path: Path) -> "ReachEnsemble":
        """Read a CSV written by :meth:`save`; ValueError when it is not one (or of another protocol version)."""
        path = Path(path)
        meta: dict = {}
        rows = []
        with open(path, encoding="utf-8") as f:
            for line in f:
                if line.startswith("#"):
                    k, sep, v = line[1:].partition(":")
                    if sep and k.strip() in ("reach_version", "key", "config", "prior", "seed", "wall_s"):
                        meta[k.strip()] = json.loads(v)
                    continue
                rows.append(line)
        if meta.get("reach_version") != REACH_VERSION or "config" not in meta or "prior" not in meta:
            raise ValueError(f"{path}: not a reach ensemble of version {REACH_VERSION}")
        r = list(csv.reader(rows))
        header, body = r[0], r[1:]
        cols = [col for col, *_ in MEASURES]
        if header != [*PARAM_NAMES, "ok", "phonates", *cols]:
            raise ValueError(f"{path}: unexpected columns {header}")
        a = np.array([[float(x) for x in row] for row in body], dtype=float).reshape(-1, len(header))
        p = len(PARAM_NAMES)
        cfg = meta["config"]
        cfg = {k: (tuple(tuple(x) if isinstance(x, list) else x for x in v) if isinstance(v, list) else v)
               for k, v in cfg.items()}
        ens = cls(config=cfg, prior=meta["prior"], params=a[:, :p], ok=a[:, p] > 0, phonates=a[:, p + 1] > 0,
                  measures={c: a[:, p + 2 + j] for j, c in enumerate(cols)}, seed=meta.get("seed"),
                  wall_s=meta.get("wall_s"), source=str(path))
        if meta.get("key") and meta["key"] != ens.key:
            raise ValueError(f"{path}: stored key {meta['key']} does not match its configuration and prior ({ens.key})")
        return ens


def draw_measures(result) -> tuple[bool, dict[str, float]]:
    """(phonates, measures) of one SimResult (module docstring: the phonation rule)."""
    from ..measures import gaw_measures
    nan = {col: math.nan for col, *_ in MEASURES}
    if result is None or isinstance(result, BaseException) or not getattr(result, "ok", False):
        return False, nan
    g = np.asarray(result.gaw, dtype=float)
    if g.size < 4 or not np.all(np.isfinite(g)):
        return False, nan
    from ..measures import cycle_table
    m = gaw_measures(g, float(result.fps))
    out = {col: float(m[col]) for col, *_ in MEASURES}
    amp = m["amplitude_mm2"]
    f0, f0_sim = m["f0_hz"], float(getattr(result, "f0", math.nan))
    if not (m["n_cycles"] >= 2 and math.isfinite(f0) and math.isfinite(amp) and amp >= PHONATION_MIN_AMPLITUDE
            and math.isfinite(f0_sim) and abs(f0 - f0_sim) <= F0_AGREEMENT * f0_sim):
        return False, out
    t = cycle_table(g, float(result.fps))
    a = t["a_max"] - t["a_min"]
    k = min(3, a.size)
    return bool(a[-k:].mean() >= SUSTAIN_RATIO * a[:k].mean()), out


def build_ensemble(config: SimConfig, prior: Prior, n: int = DEFAULT_N, seed: int = DEFAULT_SEED, *,
                   block: int = 32, progress: Callable[[int, int, float], None] | None = None,
                   simulate_fn: Callable | None = None,
                   on_error: Callable[[str], None] | None = None) -> ReachEnsemble:
    """Simulate ``n`` prior draws under ``config`` (camera rate set to ``REACH_FPS``) and measure them.

    ``progress(done, total, elapsed_s)`` is called after every block, ``on_error(message)`` for a block whose
    simulation raised (its draws count as failed). ``simulate_fn(rows, config, block)`` replaces
    :func:`vfcore.batch.simulate_many` (tests)."""
    n = int(n)
    if n < 1:
        raise ValueError(f"a reach ensemble needs n >= 1 draws, got {n}")
    if simulate_fn is None:
        from ..batch import simulate_many as simulate_fn
    cfg = config.replace(fps=min(REACH_FPS, 1.0 / config.dt), keep_trajectories=False)
    full = prior.full_array(prior.sample(n, np.random.default_rng(seed)))
    ok = np.zeros(n, bool)
    phon = np.zeros(n, bool)
    meas = {col: np.full(n, math.nan) for col, *_ in MEASURES}
    t0 = time.perf_counter()
    step = max(1, int(block))
    for s in range(0, n, step):
        rows = full[s:s + step]
        try:
            results = simulate_fn(rows, cfg, block=step)
        except Exception as exc:  # noqa: BLE001 - a failed block is counted as non-phonating draws
            results = [exc] * rows.shape[0]
            if on_error is not None:
                on_error(f"draws {s}-{s + rows.shape[0] - 1}: {type(exc).__name__}: {exc}")
        for j, r in enumerate(results):
            i = s + j
            ok[i] = bool(getattr(r, "ok", False)) and not isinstance(r, BaseException)
            phon[i], m = draw_measures(r)
            for col in meas:
                meas[col][i] = m[col]
        if progress is not None:
            progress(min(s + step, n), n, time.perf_counter() - t0)
    return ReachEnsemble(config=config_key_dict(cfg), prior=prior.to_dict(), params=full, ok=ok, phonates=phon,
                         measures=meas, seed=int(seed), wall_s=round(time.perf_counter() - t0, 1))


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
    want = _config_hash(config)
    pd = prior.to_dict()
    best = None
    for p in _candidates():
        try:
            ens = _load(p)
        except (ValueError, OSError, KeyError, IndexError):
            continue
        if _config_hash(ens.sim_config()) == want and _contains(ens.prior, pd):
            if best is None or ens.n > best.n:
                best = ens
    return best, False


# ------------------------------------------------------------------------------------------- the check
@dataclass
class ReachVerdict:
    """The outcome of :func:`check_reach`. ``verdict``: "inside", "marginal", "outside" or "unchecked"."""

    verdict: str
    message: str
    measures: dict = field(default_factory=dict)   # column -> {value, q05, q50, q95, min, max, verdict}
    n_draws: int = 0
    phonating_fraction: float = math.nan
    n_near: int | None = None
    exact: bool = True
    key: str = ""
    hints: list[str] = field(default_factory=list)

    @property
    def outside(self) -> bool:
        return self.verdict == "outside"

    def warning(self, forced_by: str) -> str | None:
        """What a fit that goes ahead says about this verdict: the message of a marginal or unchecked
        recording, and of one outside the reach fitted anyway because of ``forced_by`` (the option that
        allowed it); ``None`` inside the reach."""
        if self.verdict == "outside":
            return f"{self.message} ({forced_by}: fitting anyway; expect a posterior piled on the prior's bounds)"
        if self.verdict in ("marginal", "unchecked"):
            return self.message
        return None

    def to_dict(self) -> dict:
        def clean(x):
            if isinstance(x, dict):
                return {k: clean(v) for k, v in x.items()}
            if isinstance(x, list):
                return [clean(v) for v in x]
            if isinstance(x, float):
                return x if math.isfinite(x) else None
            return x
        return clean({"verdict": self.verdict, "message": self.message, "measures": self.measures,
                      "n_draws": self.n_draws, "phonating_fraction": self.phonating_fraction,
                      "n_near": self.n_near, "exact": self.exact, "key": self.key, "hints": list(self.hints)})


def recording_measures(gaw, fps: float) -> dict[str, float]:
    """The measures of ``MEASURES`` of a recorded GAW (mm^2 at ``fps``)."""
    from ..measures import gaw_measures
    m = gaw_measures(np.asarray(gaw, dtype=float), float(fps))
    return {col: float(m[col]) for col, *_ in MEASURES}


def _fmt(x: float, fmt: str) -> str:
    return "nan" if not math.isfinite(x) else format(x, fmt)


def _hints(outs: dict[str, str], prior: Mapping | None) -> list[str]:
    """What would help, from which hard measures are beyond the reach and on which side."""
    from .prior import TABLE2_BOUNDS
    soft = prior is not None and all(tuple(prior["bounds"].get(n, ())) == tuple(b) or n in prior.get("fixed", {})
                                     for n, b in TABLE2_BOUNDS.items())
    hints = []
    f0 = outs.get("f0_hz")
    if f0 == "high":
        hints.append(("the Table 2 priors describe a soft synthetic (silicone-like) fold; for a human voice use "
                      "--prior-set human (human tissue), or " if soft else "")
                     + "raise the stiffness and pressure bounds (--prior E_body=LO:HI --prior E_cover=LO:HI "
                       "--prior E_lig=LO:HI --prior p_sub=LO:HI) or lower rho, and check the frame rate (--fps)")
    elif f0 == "low":
        hints.append("lower the stiffness bounds (--prior E_body=LO:HI --prior E_cover=LO:HI) and check the frame "
                     "rate (--fps)")
    area = outs.get("max_area_mm2")
    if area in ("high", "low"):
        hints.append("check the area calibration (px/mm of the video: areas scale with its square), or fit an "
                     "unknown one (--uncalibrated, --area-scale LO:HI)"
                     + ("; a larger p_sub or smaller x0 opens the model wider" if area == "high"
                        else "; a smaller p_sub or larger x0 opens it less"))
    if hints:
        hints.append("a different mesh (--mesh) changes the fold's stiffness too; `vfinfer reach` builds the "
                     "ensemble of a new prior to check it first")
    return hints


def check_reach(rec: Mapping[str, float], ensemble: ReachEnsemble | None, *, exact: bool = True,
                area_scale: tuple[float, float] | None = None) -> ReachVerdict:
    """Compare a recording's measures ``rec`` (:func:`recording_measures`) with ``ensemble``.

    ``exact`` False: the ensemble is of a wider prior (:func:`find_ensemble`); then only "outside" is a
    verdict, anything else is "unchecked". ``ensemble`` None: "unchecked". ``area_scale`` ``(k_lo, k_hi)``:
    the recorded areas are ``k`` times the true ones with ``k`` unknown in that box; the peak area is then
    checked as the interval of true areas it may stand for."""
    if ensemble is None:
        return ReachVerdict("unchecked", "the model's reach was not checked: no reach ensemble matches this "
                                         "configuration and prior", exact=False)
    st = ensemble.stats()
    n, frac = ensemble.n, ensemble.phonating_fraction
    per: dict[str, dict] = {}
    outs: dict[str, str] = {}
    parts_out, parts_marg = [], []
    for col, label, unit, fmt in MEASURES:
        x = float(rec.get(col, math.nan))
        s = st[col]
        u = f" {unit}" if unit else ""
        # the true values the recorded one may stand for: one point, or an interval under an unknown area scale
        x_lo, x_hi = (x / area_scale[1], x / area_scale[0]) if (area_scale and col == "max_area_mm2") else (x, x)
        if not math.isfinite(x):
            v = "unknown"
        elif s["n"] == 0:
            v = "outside"
        elif x_hi < s["min"] or x_lo > s["max"]:
            v = "outside"
        elif x_hi < s["q05"] or x_lo > s["q95"]:
            v = "marginal"
        else:
            v = "inside"
        per[col] = {"value": x, **{k: s[k] for k in ("q05", "q50", "q95", "min", "max")}, "verdict": v,
                    "unit": unit}
        if s["n"] == 0:
            text = f"recording {label} {_fmt(x, fmt)}{u}; no prior draw of this model phonates"
        else:
            side = "most" if x > s["q50"] else "least"
            bound = s["max"] if x > s["q50"] else s["min"]
            text = (f"recording {label} {_fmt(x, fmt)}{u}; this model and prior reach {_fmt(s['q05'], fmt)}-"
                    f"{_fmt(s['q95'], fmt)}{u} (5-95 %), at {side} {_fmt(bound, fmt)}{u}")
            if x_lo != x_hi:
                text = text.replace(f"{u};", f"{u} (a true {_fmt(x_lo, fmt)}-{_fmt(x_hi, fmt)}{u} for an area scale "
                                             f"in [{area_scale[0]:g}, {area_scale[1]:g}]);", 1)
        if v == "outside":
            outs[col] = "high" if (s["n"] and x_lo > s["max"]) else "low"
            parts_out.append(text)
        elif v == "marginal":
            parts_marg.append(text)
    # joint: a draw near the recording in f0 and peak area together
    n_near = None
    f0, area = float(rec.get("f0_hz", math.nan)), float(rec.get("max_area_mm2", math.nan))
    if math.isfinite(f0) and math.isfinite(area) and area > 0:
        mf, ma = ensemble.measures["f0_hz"], ensemble.measures["max_area_mm2"]
        with np.errstate(invalid="ignore", divide="ignore"):
            a_lo, a_hi = (area / area_scale[1], area / area_scale[0]) if area_scale else (area, area)
            near = (ensemble.phonates & (np.abs(mf - f0) <= NEAR_F0 * f0) & (ma >= a_lo / NEAR_AREA)
                    & (ma <= a_hi * NEAR_AREA))
        n_near = int(np.count_nonzero(near))
    hard_out = any(c in outs for c in HARD_MEASURES)
    if hard_out:
        verdict = "outside"
    elif outs or parts_marg or n_near == 0:
        verdict = "marginal"
    else:
        verdict = "inside"
    hints = _hints(outs, ensemble.prior) if verdict != "inside" else []
    where = (f"{int(round(frac * n))} of {n} prior draws phonate" + ("" if exact else
             "; ensemble of a wider prior, which contains this one"))
    if verdict == "outside":
        msg = ("recording outside this model's reach: " + "; ".join(parts_out)
               + f" ({where})" + ("; also " + "; ".join(parts_marg) if parts_marg else ""))
    elif verdict == "marginal":
        bits = parts_out + parts_marg
        if n_near == 0:
            bits.append(f"no phonating draw has f0 within {NEAR_F0:.0%} and peak area within a factor "
                        f"{NEAR_AREA:g} of the recording's together")
        msg = "recording at the margin of this model's reach: " + "; ".join(bits) + f" ({where})"
    else:
        msg = (f"recording inside this model's reach: f0 {_fmt(f0, '.0f')} Hz, peak area {_fmt(area, '.3g')} mm^2 "
               f"({n_near} draws near it; {where})")
    if hints:
        msg += "; what would help: " + "; ".join(hints)
    if not exact and verdict != "outside":
        return ReachVerdict("unchecked", "the model's reach was not checked exactly: no reach ensemble of this "
                            "prior; the recording is within the reach of a wider prior's ensemble for this "
                            "configuration", per, n, frac, n_near, False, ensemble.key, [])
    return ReachVerdict(verdict, msg, per, n, frac, n_near, exact, ensemble.key, hints)


def reach_for(gaw, fps: float, config: SimConfig, prior: Prior,
              area_scale: tuple[float, float] | None = None) -> ReachVerdict:
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
    args = [f"--mesh {config.mesh}", f"--dt {config.dt:g}", f"--duration {config.duration:g}",
            f"--discard {config.discard:g}"]
    if config.element != "p1":
        args.append(f"--element {config.element}")
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


def format_table(ens: ReachEnsemble) -> str:
    """Markdown table of an ensemble's reach (docs/inference.md, "The model's reach")."""
    st = ens.stats()
    lines = ["| measure | unit | 5 % | 50 % | 95 % | min | max |", "|---|---|---|---|---|---|---|"]
    for col, label, unit, fmt in MEASURES:
        s = st[col]
        lines.append(f"| {label} | {unit or '1'} | " + " | ".join(_fmt(s[k], fmt) for k in ("q05", "q50", "q95",
                                                                                          "min", "max")) + " |")
    lines.append(f"\n{int(ens.phonates.sum())} of {ens.n} draws phonate ({ens.phonating_fraction:.1%}); "
                 f"{int(ens.ok.sum())} simulations succeeded.")
    return "\n".join(lines)


__all__ = ["REACH_VERSION", "MEASURES", "ReachEnsemble", "ReachVerdict", "build_ensemble", "cache_dir",
           "check_reach", "find_ensemble", "format_table", "reach_for", "reach_key", "recording_measures",
           "save_cached"]
