"""The result of an inference: a weighted ensemble plus its resampled (equally weighted) copy.

Posterior mean and standard deviation are the self-normalised weighted moments; "% of the
estimate" is ``100 sd / |mean|`` as in Hadwin et al. (2019), Tables 3-5. Quantiles come
from the weighted empirical CDF. The resampled ensemble (systematic resampling) is what
posterior-predictive products and t-tests use.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..params import PARAM_UNITS
from .diagnostics import degeneracy_warnings, normalize_log_weights, systematic_resample, weighted_quantiles
from .diagnostics import ess as _ess
from .diagnostics import pareto_k as _pareto_k
from .evaluation import Evaluation

QUANTILE_LEVELS = (0.025, 0.05, 0.25, 0.5, 0.75, 0.95, 0.975)


@dataclass(eq=False)
class Posterior:
    """Weighted posterior ensemble.

    Attributes
    ----------
    names : estimated parameter names (columns of ``samples``).
    samples : (N, d) draws, paper units.
    log_weights : (N,) normalised log weights (``logsumexp == 0``; ``-inf`` = zero weight).
    resampled : (M,) row indices of ``samples`` after systematic resampling.
    ess, pareto_k : diagnostics of the weights (for SMC: of the last reweighting step).
    log_evidence, log_evidence_se : ``log p(y)`` and its Monte Carlo standard error.
    n_simulations, n_failed : forward simulations run / failed.
    predictive : per-draw model outputs (aligned GAW, flow rate, contact) for the rows
        ``predictive_index`` of ``samples`` (None when the likelihood is not the FE model).
    area_scale : ``(k_lo, k_hi)`` of the problem's unknown area scale (``Problem.area_scale``), or None:
        the recording's areas are ``k`` times the model's (:meth:`recorded_gaws`).
    model : the forward model's settings the draws were simulated with (``SimConfig.as_dict()``), so that a
        posterior read back is used only with the model it belongs to; None when unknown (not the FE model,
        or a file written before it was recorded).
    """

    names: tuple[str, ...]
    samples: np.ndarray
    log_weights: np.ndarray
    resampled: np.ndarray
    ess: float
    pareto_k: float
    log_evidence: float
    log_evidence_se: float
    n_simulations: int
    n_failed: int = 0
    method: str = "importance"
    warnings: list[str] = field(default_factory=list)
    predictive: Evaluation | None = None
    predictive_index: np.ndarray | None = None
    obs_gaw: np.ndarray | None = None
    fps: float | None = None
    info: dict = field(default_factory=dict)
    area_scale: tuple | None = None
    model: dict | None = None

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_weighted(
        cls,
        names,
        samples,
        log_weights,
        *,
        rng: np.random.Generator,
        n_resample: int | None = None,
        log_evidence: float = math.nan,
        log_evidence_se: float = math.nan,
        n_simulations: int = 0,
        n_failed: int = 0,
        method: str = "importance",
        ess_min: float = 100.0,
        check: bool = True,
        **kw,
    ) -> Posterior:
        samples = np.atleast_2d(np.asarray(samples, dtype=float))
        lw = normalize_log_weights(log_weights)
        if samples.shape != (lw.size, len(names)):
            raise ValueError(f"samples shape {samples.shape} does not match {lw.size} weights x {len(names)} names")
        w = np.exp(lw)
        m = int(n_resample) if n_resample is not None else lw.size
        res = systematic_resample(w, m, rng)
        e = _ess(lw)
        k = _pareto_k(lw)
        msgs = list(kw.pop("warnings", []))
        if check:
            msgs += degeneracy_warnings(e, lw.size, k, ess_min=ess_min, label=method)
        return cls(
            names=tuple(names),
            samples=samples,
            log_weights=lw,
            resampled=res,
            ess=e,
            pareto_k=k,
            log_evidence=float(log_evidence),
            log_evidence_se=float(log_evidence_se),
            n_simulations=int(n_simulations),
            n_failed=int(n_failed),
            method=method,
            warnings=msgs,
            **kw,
        )

    # ------------------------------------------------------------------ moments
    @property
    def ndim(self) -> int:
        return len(self.names)

    @property
    def weights(self) -> np.ndarray:
        return np.exp(self.log_weights)

    @property
    def mean(self) -> np.ndarray:
        return self.weights @ self.samples

    @property
    def cov(self) -> np.ndarray:
        d = self.samples - self.mean
        return (d * self.weights[:, None]).T @ d

    @property
    def sd(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.cov), 0.0, None))

    @property
    def pct(self) -> np.ndarray:
        """Standard deviation as a percentage of the estimate (Tables 3-5)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return 100.0 * self.sd / np.abs(self.mean)

    def quantile(self, q) -> np.ndarray:
        """Weighted quantiles, shape (len(q), d) (or (d,) for scalar q)."""
        w = self.weights
        out = np.stack([weighted_quantiles(self.samples[:, j], w, np.atleast_1d(q)) for j in range(self.ndim)], axis=-1)
        return out[0] if np.ndim(q) == 0 else out

    @property
    def quantiles(self) -> dict[float, np.ndarray]:
        qs = self.quantile(QUANTILE_LEVELS)
        return {q: qs[i] for i, q in enumerate(QUANTILE_LEVELS)}

    def credible_interval(self, level: float = 0.9) -> tuple[np.ndarray, np.ndarray]:
        """Central (equal-tailed) credible interval, (lo (d,), hi (d,))."""
        a = 0.5 * (1.0 - level)
        q = self.quantile([a, 1.0 - a])
        return q[0], q[1]

    @property
    def resampled_samples(self) -> np.ndarray:
        return self.samples[self.resampled]

    def recorded_gaws(self) -> np.ndarray:
        """The resampled draws' predicted GAWs as the camera records them, succeeded draws only,
        ``(n_ok, n_frames)`` mm^2: the model's areas, or with an unknown area scale each draw's areas times
        its least-squares ``k = y.A / A.A`` against the recording, clipped to the box (the centre of ``k``'s
        conditional given the draw, :ref:`inference-scale-unknown-area-scale`), so that residuals and measures
        compare like with like. ValueError without predictions."""
        rp = self.resampled_predictive()
        if rp is None or rp.gaw is None:
            raise ValueError("the posterior carries no predictions (not an FE fit)")
        g = np.asarray(rp.gaw, dtype=float)[np.asarray(rp.ok, dtype=bool)]
        if self.area_scale is None or self.obs_gaw is None or g.size == 0:
            return g
        y = np.asarray(self.obs_gaw, dtype=float)[: g.shape[1]]
        S = np.einsum("ij,ij->i", g, g)
        with np.errstate(invalid="ignore", divide="ignore"):
            k = np.where(S > 0.0, (g @ y) / S, 1.0)
        k = np.clip(k, float(self.area_scale[0]), float(self.area_scale[1]))
        return g * k[:, None]

    def resampled_predictive(self) -> Evaluation | None:
        """Model outputs for each resampled draw (rows aligned with ``resampled``)."""
        if self.predictive is None:
            return None
        if self.predictive_index is None:
            return self.predictive.take(self.resampled)
        pos = {int(r): i for i, r in enumerate(self.predictive_index)}
        try:
            rows = np.array([pos[int(r)] for r in self.resampled])
        except KeyError:
            raise RuntimeError("predictive outputs do not cover the resampled draws") from None
        return self.predictive.take(rows)

    def as_dict(self) -> dict[str, dict[str, float]]:
        return {n: {"mean": float(self.mean[i]), "sd": float(self.sd[i])} for i, n in enumerate(self.names)}

    # ------------------------------------------------------------------ tables
    def summary_table(self) -> list[dict]:
        """One row per parameter: mean, sd, % of estimate, 5/50/95% quantiles (paper units)."""
        q = self.quantile([0.05, 0.5, 0.95])
        mean, sd, pct = self.mean, self.sd, self.pct
        return [
            {
                "name": n,
                "unit": PARAM_UNITS.get(n, ""),
                "mean": float(mean[i]),
                "sd": float(sd[i]),
                "pct": float(pct[i]),
                "q05": float(q[0, i]),
                "q50": float(q[1, i]),
                "q95": float(q[2, i]),
            }
            for i, n in enumerate(self.names)
        ]

    def format_summary(self) -> str:
        lines = [f"{'parameter':<9} {'unit':<7} {'mean':>11} {'sd':>10} {'%':>6} {'q05':>11} {'q95':>11}"]
        for r in self.summary_table():
            lines.append(
                f"{r['name']:<9} {r['unit']:<7} {r['mean']:11.5g} {r['sd']:10.4g} {r['pct']:6.2f} "
                f"{r['q05']:11.5g} {r['q95']:11.5g}"
            )
        lines.append(
            f"method={self.method} N={self.samples.shape[0]} ESS={self.ess:.1f} "
            f"pareto_k={self.pareto_k:.2f} log_evidence={self.log_evidence:.3f}+-"
            f"{self.log_evidence_se:.3f} n_simulations={self.n_simulations} n_failed={self.n_failed}"
        )
        lines += [f"WARNING: {w}" for w in self.warnings]
        return "\n".join(lines)

    def _meta(self) -> dict:
        return {
            "names": list(self.names),
            "method": self.method,
            "ess": self.ess,
            "pareto_k": self.pareto_k,
            "log_evidence": self.log_evidence,
            "log_evidence_se": self.log_evidence_se,
            "n_simulations": self.n_simulations,
            "n_failed": self.n_failed,
            "warnings": list(self.warnings),
            "fps": self.fps,
            "model": self.model,
        }

    # ------------------------------------------------------------------ ArviZ / NetCDF
    def to_inference_data(self):
        """ArviZ InferenceData.

        ``posterior``: the resampled ensemble (chain 1, draw M) plus ``sample_index`` (row of
        the weighted sample each draw came from); ``weighted_samples`` group: all N draws and
        their normalised ``log_weight``; ``posterior_predictive`` / ``observed_data``: aligned
        GAW when available. Scalars (ESS, Pareto-k, evidence, counts, warnings) are attrs.
        """
        import arviz as az
        import xarray as xr

        res = self.resampled
        post = {n: (("chain", "draw"), self.samples[res, j][None, :]) for j, n in enumerate(self.names)}
        post["sample_index"] = (("chain", "draw"), res[None, :].astype(np.int64))
        attrs = {k: (json.dumps(v) if isinstance(v, (list, dict)) or v is None else v) for k, v in self._meta().items()}
        groups = {"posterior": xr.Dataset(post, attrs=attrs)}
        ws = {n: (("sample",), self.samples[:, j]) for j, n in enumerate(self.names)}
        ws["log_weight"] = (("sample",), self.log_weights)
        groups["weighted_samples"] = xr.Dataset(ws, attrs=attrs)
        rp = self.resampled_predictive()
        if rp is not None and rp.gaw is not None:
            pp = {"gaw": (("chain", "draw", "frame"), rp.gaw.astype(np.float64)[None])}
            for nm in ("mean_flow", "mean_contact", "max_contact", "contact_impulse", "contact_pressure_in_contact"):
                if getattr(rp, nm) is not None:
                    pp[nm] = (("chain", "draw"), getattr(rp, nm)[None])
            groups["posterior_predictive"] = xr.Dataset(pp)
        if self.obs_gaw is not None:
            groups["observed_data"] = xr.Dataset({"gaw": (("frame",), np.asarray(self.obs_gaw, dtype=float))})
        import warnings as _w

        with _w.catch_warnings():
            _w.simplefilter("ignore")
            return az.InferenceData(**groups)

    def to_netcdf(self, path) -> Path:
        path = Path(path)
        self.to_inference_data().to_netcdf(str(path))
        return path

    @classmethod
    def from_inference_data(cls, idata) -> Posterior:
        ws = idata["weighted_samples"]
        attrs = dict(idata["posterior"].attrs)
        names = tuple(json.loads(attrs["names"]))
        samples = np.stack([ws[n].values for n in names], axis=1)
        res = idata["posterior"]["sample_index"].values[0].astype(np.int64)
        pred = None
        if "posterior_predictive" in idata.groups():
            pp = idata["posterior_predictive"]
            g = pp["gaw"].values[0]
            pred = Evaluation(
                loglik=np.zeros(g.shape[0]),
                ok=np.all(np.isfinite(g), axis=1),
                gaw=g.astype(np.float32),
                mean_flow=pp["mean_flow"].values[0],
                mean_contact=pp["mean_contact"].values[0],
                max_contact=pp["max_contact"].values[0],
                **{nm: pp[nm].values[0] for nm in ("contact_impulse", "contact_pressure_in_contact") if nm in pp},
            )
        obs = idata["observed_data"]["gaw"].values if "observed_data" in idata.groups() else None
        fps = json.loads(attrs["fps"]) if isinstance(attrs.get("fps"), str) else attrs.get("fps")
        post = cls(
            names=names,
            samples=samples,
            log_weights=ws["log_weight"].values.astype(float),
            resampled=res,
            ess=float(attrs["ess"]),
            pareto_k=float(attrs["pareto_k"]),
            log_evidence=float(attrs["log_evidence"]),
            log_evidence_se=float(attrs["log_evidence_se"]),
            n_simulations=int(attrs["n_simulations"]),
            n_failed=int(attrs["n_failed"]),
            method=str(attrs["method"]),
            warnings=list(json.loads(attrs["warnings"])),
            obs_gaw=obs,
            fps=fps,
            model=json.loads(attrs["model"]) if "model" in attrs else None,
        )
        if pred is not None:
            # predictive rows follow the resampled draws (duplicates are identical rows)
            post.predictive = pred
            post.predictive_index = res.copy()
        return post

    @classmethod
    def from_netcdf(cls, path) -> Posterior:
        import arviz as az

        return cls.from_inference_data(az.from_netcdf(str(path)))

    # ------------------------------------------------------------------ CSV
    def to_csv(self, path) -> Path:
        """All weighted draws: one row each with the parameters, ``log_weight``, ``weight`` and
        ``n_resampled`` (times the draw occurs in the resampled ensemble). A ``#`` header line
        carries the scalar diagnostics as JSON."""
        path = Path(path)
        counts = np.bincount(self.resampled, minlength=self.samples.shape[0])
        w = self.weights
        with open(path, "w", newline="") as fh:
            fh.write("# " + json.dumps(self._meta()) + "\n")
            wr = csv.writer(fh)
            wr.writerow(list(self.names) + ["log_weight", "weight", "n_resampled"])
            for i in range(self.samples.shape[0]):
                wr.writerow(
                    [repr(float(v)) for v in self.samples[i]]
                    + [repr(float(self.log_weights[i])), repr(float(w[i])), int(counts[i])]
                )
        return path

    @classmethod
    def from_csv(cls, path) -> Posterior:
        with open(path, newline="") as fh:
            first = fh.readline()
            if not first.startswith("# "):
                raise ValueError(f"{path}: not a vfinfer posterior CSV (missing '# ' metadata line)")
            meta = json.loads(first[2:])
            rows = list(csv.reader(fh))
        header, body = rows[0], rows[1:]
        names = tuple(meta["names"])
        if header[: len(names)] != list(names):
            raise ValueError(f"{path}: header {header} does not match names {names}")
        arr = np.array([[float(v) for v in r[: len(names) + 1]] for r in body])
        counts = np.array([int(r[len(names) + 2]) for r in body])
        return cls(
            names=names,
            samples=arr[:, : len(names)],
            log_weights=arr[:, len(names)],
            resampled=np.repeat(np.arange(len(body)), counts),
            ess=float(meta["ess"]),
            pareto_k=float(meta["pareto_k"]),
            log_evidence=float(meta["log_evidence"]),
            log_evidence_se=float(meta["log_evidence_se"]),
            n_simulations=int(meta["n_simulations"]),
            n_failed=int(meta["n_failed"]),
            method=meta["method"],
            warnings=list(meta["warnings"]),
            fps=meta.get("fps"),
            model=meta.get("model"),
        )
