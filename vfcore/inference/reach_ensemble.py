"""A reach ensemble: prior draws of one simulation configuration, simulated and measured.

``N`` independent draws from the prior are simulated in lock-step (:func:`vfcore.batch.simulate_many`) and each
draw's GAW is measured (:mod:`vfcore.measures`: f0, peak area, open / speed / closing quotients) with whether it
phonates (the rule is in :mod:`.reach`'s docstring and :func:`draw_measures`). An ensemble is keyed by
:func:`reach_key`, a hash of the configuration's physics and numerics and of the prior, and stored as a CSV with
its metadata in comment lines (:meth:`ReachEnsemble.save`). Where ensembles are looked up and how a recording is
checked against one live in :mod:`.reach` and :mod:`.reach_verdict`.
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
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

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
QUANTILES = (0.05, 0.5, 0.95)
#: Draws of a shipped ensemble and of ``vfinfer reach`` unless told otherwise.
DEFAULT_N = 2000
DEFAULT_SEED = 20190613

# early_stop only ends simulations whose response has settled, which changes no ensemble statistic
_KEY_EXCLUDE = ("fps", "keep_trajectories", "early_stop")


# ------------------------------------------------------------------------------------------- keys
def _canonical(x):
    if isinstance(x, Mapping):
        return {str(k): _canonical(v) for k, v in sorted(x.items())}
    if isinstance(x, (list, tuple)):
        return [_canonical(v) for v in x]
    if isinstance(x, (float, int, np.floating, np.integer)) and not isinstance(x, bool):
        return repr(float(x))  # 1 and 1.0 are one value; repr keeps every digit
    return x


def config_key_dict(config: SimConfig) -> dict:
    """The part of ``config`` a reach ensemble depends on (everything but the camera rate and trajectories)."""
    d = {k: v for k, v in config.as_dict().items() if k not in _KEY_EXCLUDE}
    if d["contact"] == "projection":
        # the layer options do not enter the physics of the rigid projection: its key leaves them out
        del d["contact"], d["contact_layer_mm"]
    if d.get("flow") == "paper":
        # the ensembles made before the flow load was a setting are the paper's rule: its key leaves it out
        del d["flow"]
    return d


def reach_key(config: SimConfig, prior: Prior) -> str:
    """Hex key (16 digits of SHA-256) of the ensemble for ``config`` and ``prior``."""
    blob = json.dumps(
        {"version": REACH_VERSION, "config": _canonical(config_key_dict(config)), "prior": _canonical(prior.to_dict())},
        sort_keys=True,
        separators=(",", ":"),
    )
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def config_hash(config: SimConfig) -> str:
    """Hex key of ``config`` alone: ensembles of one configuration under different priors share it."""
    blob = json.dumps({"version": REACH_VERSION, "config": _canonical(config_key_dict(config))}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


# ------------------------------------------------------------------------------------------- ensemble
@dataclass
class ReachEnsemble:
    """A prior-predictive ensemble: per draw the seven parameters, success, phonation and the measures."""

    config: dict  # config_key_dict of the SimConfig it was simulated with
    prior: dict  # Prior.to_dict()
    params: np.ndarray  # (N, 7) PARAM_NAMES order, paper units
    ok: np.ndarray  # (N,) bool: simulation succeeded
    phonates: np.ndarray  # (N,) bool
    measures: dict[str, np.ndarray]  # column -> (N,), nan where undefined
    key: str = ""
    seed: int | None = None
    wall_s: float | None = None
    source: str = ""  # where it was read from

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
                out[col] = {
                    "q05": float(q[0]),
                    "q50": float(q[1]),
                    "q95": float(q[2]),
                    "min": float(v.min()),
                    "max": float(v.max()),
                    "n": int(v.size),
                }
            else:
                out[col] = {"q05": math.nan, "q50": math.nan, "q95": math.nan, "min": math.nan, "max": math.nan, "n": 0}
        return out

    # -------------------------------------------------------------------------------- CSV
    def to_csv_text(self) -> str:
        buf = io.StringIO()
        meta = {
            "reach_version": REACH_VERSION,
            "key": self.key,
            "config": self.config,
            "prior": self.prior,
            "n_draws": self.n,
            "seed": self.seed,
            "wall_s": self.wall_s,
            "fps": self.sim_config().fps,
            "phonation_min_amplitude_mm2": PHONATION_MIN_AMPLITUDE,
        }
        buf.write("# vfinfer reach ensemble (vfcore.inference.reach): prior draws simulated and measured\n")
        for k, v in meta.items():
            buf.write(f"# {k}: {json.dumps(v, sort_keys=True)}\n")
        w = csv.writer(buf, lineterminator="\n")
        cols = [col for col, *_ in MEASURES]
        w.writerow([*PARAM_NAMES, "ok", "phonates", *cols])
        for i in range(self.n):
            w.writerow(
                [
                    *(f"{x:.10g}" for x in self.params[i]),
                    int(self.ok[i]),
                    int(self.phonates[i]),
                    *("nan" if not math.isfinite(self.measures[c][i]) else f"{self.measures[c][i]:.6g}" for c in cols),
                ]
            )
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
            os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes it private; an ensemble is not
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise
        return path

    @classmethod
    def load(cls, path: Path) -> ReachEnsemble:
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
        cfg = {
            k: (tuple(tuple(x) if isinstance(x, list) else x for x in v) if isinstance(v, list) else v)
            for k, v in cfg.items()
        }
        ens = cls(
            config=cfg,
            prior=meta["prior"],
            params=a[:, :p],
            ok=a[:, p] > 0,
            phonates=a[:, p + 1] > 0,
            measures={c: a[:, p + 2 + j] for j, c in enumerate(cols)},
            seed=meta.get("seed"),
            wall_s=meta.get("wall_s"),
            source=str(path),
        )
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
    if not (
        m["n_cycles"] >= 2
        and math.isfinite(f0)
        and math.isfinite(amp)
        and amp >= PHONATION_MIN_AMPLITUDE
        and math.isfinite(f0_sim)
        and abs(f0 - f0_sim) <= F0_AGREEMENT * f0_sim
    ):
        return False, out
    t = cycle_table(g, float(result.fps))
    a = t["a_max"] - t["a_min"]
    k = min(3, a.size)
    return bool(a[-k:].mean() >= SUSTAIN_RATIO * a[:k].mean()), out


def build_ensemble(
    config: SimConfig,
    prior: Prior,
    n: int = DEFAULT_N,
    seed: int = DEFAULT_SEED,
    *,
    block: int = 32,
    progress: Callable[[int, int, float], None] | None = None,
    simulate_fn: Callable | None = None,
    on_error: Callable[[str], None] | None = None,
) -> ReachEnsemble:
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
        rows = full[s : s + step]
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
    return ReachEnsemble(
        config=config_key_dict(cfg),
        prior=prior.to_dict(),
        params=full,
        ok=ok,
        phonates=phon,
        measures=meas,
        seed=int(seed),
        wall_s=round(time.perf_counter() - t0, 1),
    )
