"""Reducer: log-likelihoods in the store -> vfcore Posterior -> summaries, CSV, NetCDF and figures in the store.

All statistics are vfcore.inference's (``reduce_importance``, ``Posterior``); this module only
moves arrays between the store and those functions and renders figures.  It runs as a Dask task
(so the service process stays responsive) and is deterministic: the same store gives the same
posterior bytes.
"""

from __future__ import annotations

import io
import math
import os
import tempfile
from pathlib import Path

import numpy as np

from vfcore.inference.problem import model_record
from vfcore.params import PARAM_UNITS
from vfcore.strict_json import jsonable

from . import store as st
from .jobspec import JobSpec

#: Posterior-predictive summaries. ``contact_impulse`` (per cycle and unit fold length) and
#: ``contact_pressure_in_contact`` (mean over the contact patch while in contact) are the contact
#: products to read; ``mean_contact`` / ``max_contact`` are the paper's nodal peak pressures, which grow
#: as the time step shrinks and change with the mesh (:ref:`model-contact`).
SUMMARY_QUANTITIES = {
    "mean_flow": "m^3/s",
    "contact_impulse": "N s/m",
    "contact_pressure_in_contact": "Pa",
    "mean_contact": "Pa",
    "max_contact": "Pa",
}
#: Summaries that are not converged: their entries carry ``"converged": False`` and ``"depends_on"``, the
#: resolution they depend on. With the compliant contact layer the nodal peaks converge in the time step but,
#: like every contact quantity, not in the mesh (:ref:`model-contact`).
UNCONVERGED = frozenset({"mean_contact", "max_contact"})
DEPENDS_ON = {"projection": "mesh and time step", "layer": "mesh"}


def convergence_note(q: dict) -> str:
    """`` (depends on mesh and time step)`` for a predictive summary entry that is not converged, else ``""``:
    the one wording of the terminal and the HTML report, so that neither shows such a number bare."""
    return "" if q.get("converged", True) else f" (depends on {q.get('depends_on', 'mesh and time step')})"


def reduce_is_job(store_path: str) -> dict:
    """Importance-sampling reducer (a Dask task): read batch 0, reduce, publish."""
    from vfcore.inference.importance import reduce_importance

    root = st.open_store(Path(store_path))
    spec = JobSpec.model_validate(dict(root.attrs["jobspec"]))
    problem = spec.to_problem()
    g = root[st.batch_path(0)]
    thetas = g["thetas"][...]
    ev = st.read_evaluation(g)
    post = reduce_importance(thetas, ev, problem.prior.names, spec.seed, obs_gaw=problem.obs_compared, fps=problem.fps)
    post.info["n_draws"] = int(thetas.shape[0])
    return publish_posterior(store_path, post, spec)


def _finite_gaw(pred) -> np.ndarray | None:
    """The resampled draws' predicted GAWs (float64), rows with a non-finite value dropped."""
    if pred is None or pred.gaw is None:
        return None
    g = np.asarray(pred.gaw, dtype=float)
    return g[np.all(np.isfinite(g), axis=1)]


def _predictive_summary(pred, contact: str = "projection") -> tuple[dict, np.ndarray | None]:
    """Summary quantities and 5/50/95 % GAW bands of ``pred``, a posterior's resampled predictive
    (``contact``: the job's contact law, which sets what the nodal peak pressures depend on)."""
    out = {}
    bands = None
    if pred is None:
        return out, bands
    for name, unit in SUMMARY_QUANTITIES.items():
        a = getattr(pred, name)
        if a is None:
            continue
        a = np.asarray(a, dtype=float)
        a = a[np.isfinite(a)]
        if a.size == 0:
            continue
        q = np.quantile(a, [0.05, 0.5, 0.95])
        out[name] = {
            "unit": unit,
            "mean": float(a.mean()),
            "sd": float(a.std(ddof=1)) if a.size > 1 else 0.0,
            "q05": float(q[0]),
            "q50": float(q[1]),
            "q95": float(q[2]),
        }
        if name in UNCONVERGED:
            out[name]["converged"] = False
            out[name]["depends_on"] = DEPENDS_ON[contact]
    g = _finite_gaw(pred)
    if g is not None and g.shape[0]:
        bands = np.quantile(g, [0.05, 0.5, 0.95], axis=0)
    return out, bands


def posterior_summary(post, pred: dict | None = None) -> dict:
    if pred is None:
        pred, _ = _predictive_summary(post.resampled_predictive())
    info = {
        k: v
        for k, v in post.info.items()
        if k
        in (
            "generations",
            "n_generations",
            "n_particles",
            "temperatures",
            "max_loglik",
            "n_draws",
            "failure_messages",
            "runs",
            "runs_kept",
            "run_rule",
            "run_gap",
        )
    }
    return jsonable(
        {
            "method": post.method,
            "names": list(post.names),
            "units": {n: PARAM_UNITS[n] for n in post.names},
            "table": post.summary_table(),
            "ess": post.ess,
            "pareto_k": post.pareto_k,
            "log_evidence": post.log_evidence,
            "log_evidence_se": post.log_evidence_se,
            "n_simulations": post.n_simulations,
            "n_failed": post.n_failed,
            "n_samples": int(post.samples.shape[0]),
            "n_resampled": int(post.resampled.size),
            "warnings": list(post.warnings),
            "predictive": pred,
            "info": info,
            "formatted": post.format_summary(),
        }
    )


def regularity_of(spec: JobSpec, post) -> dict | None:
    """The regularity check (vfcore.diagnose.regularity; 7 simulations) at the posterior's heaviest
    sample of an FE job: is the fitted vibration regular, so that the waveform likelihood is a
    smooth function of the parameters? ``None`` for another model; an error is reported, not raised
    (:ref:`inference-samplers-irregular-and-aperiodic-vibration-the`)."""
    if spec.model != "fe":
        return None
    try:
        from vfcore.diagnose.regularity import sensitivity

        theta = np.asarray(post.samples, dtype=float)[int(np.argmax(post.log_weights))]
        return sensitivity(spec.to_problem(), theta, seed=spec.seed).to_dict()
    except Exception as exc:  # noqa: BLE001 - a check must not fail the job; recorded
        return {"error": f"{type(exc).__name__}: {exc}"}


def regularity_warning(reg: dict | None) -> str | None:
    """The summary's warning for the regularity check's dict (:func:`regularity_of`), or None when the fit is
    smooth, the check did not run or it failed (its error is recorded in the summary)."""
    if not reg or "error" in reg:
        return None
    if reg.get("irregular"):
        return (
            f"IRREGULAR VIBRATION: at the heaviest sample a relative {reg['step']:g} change of the parameters "
            f"changes the log-likelihood by up to {reg['max_change']:.3g} nats; the waveform likelihood is rough "
            "here and the posterior reflects which points were simulated (docs/inference.md, 'Irregular vibration')"
        )
    if reg.get("rough"):
        from vfcore.diagnose.regularity import rough_phrase

        return (
            f"ROUGH LIKELIHOOD: at the heaviest sample {rough_phrase(reg)}; the likelihood is "
            "a staircase at the scale of the posterior and its intervals are not calibrated (docs/inference.md, "
            "'Aperiodic vibration')"
        )
    return None


def runs_warning(spec: JobSpec) -> str | None:
    """The summary's warning for a single SMC run where all six scaled parameters are estimated: one run cannot
    show that it missed a basin, and on six-parameter twins single runs covered about two thirds of what their
    90 % intervals claimed (:ref:`inference-samplers-independent-runs`); None otherwise."""
    from vfcore.inference.identify import SCALED

    sampler = spec.sampler
    if getattr(sampler, "kind", None) != "smc" or sampler.runs > 1:
        return None
    if not set(SCALED) <= set(spec.to_prior().names):
        return None
    return (
        "ONE RUN: a single SMC run of six free material parameters cannot show whether it missed a basin of "
        "the likelihood; independent runs that agree are the check (sampler.runs = 3, --runs 3 on the "
        "command line; cost x3) (docs/inference.md, 'Independent runs' and 'Do the runs agree?')"
    )


def identifiability_of(spec: JobSpec, post) -> dict | None:
    """The identifiability table of the posterior (vfcore.inference.identify: per parameter, principal
    directions, the common scale of the six scaled parameters and the combinations a GAW determines),
    as a dict; an error is reported, not raised."""
    try:
        from vfcore.inference.identify import identify

        return identify(post, spec.to_prior(), spec.measurements).to_dict()
    except Exception as exc:  # noqa: BLE001 - a table must not fail the job; recorded
        return {"error": f"{type(exc).__name__}: {exc}"}


#: residual RMS / sigma_e beyond which (either way) a fixed-noise job's summary warns
NOISE_RATIO_WARN = 1.5
#: residual RMS / the recording's own noise sd (second differences) above which the summary says the model
#: does not reproduce the recording; a fit to within the noise has a ratio near 1
MISFIT_RATIO_WARN = 3.0


def noise_check(spec: JobSpec, post, pred) -> dict | None:
    """The fit's residual RMS against the noise model (mm^2): per resampled draw
    ``sqrt(mean((A - y)^2))`` over the compared frames (with ``noise="marginal"`` this is the noise
    sd's estimate; with ``"fixed"`` it tells whether ``sigma_e`` fits: a residual ``r`` against
    ``sigma_e`` makes the posterior about ``r / sigma_e`` times too narrow if the misfit is noise).
    ``pred``: the posterior's resampled predictive. ``None`` when there are no predictions or no
    stored observation."""
    g = _finite_gaw(pred)
    if g is None or g.shape[0] == 0 or post.obs_gaw is None:
        return None
    from vfcore.diagnose.locate import noise_sd

    y = np.asarray(post.obs_gaw, dtype=float)[: g.shape[1]]
    rms = np.sqrt(np.mean((g - y) ** 2, axis=1))
    q = np.quantile(rms, [0.05, 0.5, 0.95])
    s_rec = noise_sd(y, g)
    return {
        "noise": spec.noise,
        "sigma_e": float(spec.sigma_e),
        "residual_rms": {"unit": "mm2", "q05": float(q[0]), "q50": float(q[1]), "q95": float(q[2])},
        "ratio": float(q[1] / spec.sigma_e),
        "recording_noise_sd": s_rec,
        "misfit_ratio": float(q[1] / s_rec) if s_rec > 0 else None,
    }


#: share of the area scale's box within which a 5 % / 95 % posterior quantile counts as piled on a bound
AREA_SCALE_EDGE = 0.01


def area_scale_of(spec: JobSpec, pred) -> dict | None:
    """The posterior of the unknown area scale ``k`` (recorded / true area) of a job with ``area_scale``: one
    draw of ``k`` per resampled draw from its conditional given that draw's aligned segment
    (:meth:`vfcore.inference.problem.Problem.sample_area_scale`), summarised; ``pred`` (the resampled predictive)
    has its segments multiplied by their ``k`` in place, so that the fit figure, bands and noise check compare
    what the camera would record with the recording. ``None`` for a calibrated job or without predictions.
    Deterministic in the job's seed."""
    if spec.area_scale is None or pred is None or pred.gaw is None or len(pred) == 0:
        return None
    problem = spec.to_problem()
    rng = np.random.default_rng(np.random.SeedSequence(spec.seed, spawn_key=(0xA5CA1E,)))
    g = np.asarray(pred.gaw, dtype=float)
    ks = np.array([problem.sample_area_scale(row, rng) if np.all(np.isfinite(row)) else math.nan for row in g])
    pred.gaw = (g * ks[:, None]).astype(pred.gaw.dtype)
    k = ks[np.isfinite(ks)]
    if k.size == 0:
        return None
    lo, hi = problem.area_scale
    q = np.quantile(k, [0.05, 0.5, 0.95])
    out = {
        "unit": "1",
        "prior": [lo, hi],
        "mean": float(k.mean()),
        "sd": float(k.std(ddof=1)) if k.size > 1 else 0.0,
        "q05": float(q[0]),
        "q50": float(q[1]),
        "q95": float(q[2]),
        "px_per_mm_factor": {"q05": math.sqrt(q[0]), "q50": math.sqrt(q[1]), "q95": math.sqrt(q[2])},
        "meaning": "k = recorded area / true area = (true px/mm / assumed px/mm)^2",
    }
    out["formatted"] = (
        f"area scale k (recorded / true area): {out['mean']:.4g} +- {out['sd']:.3g} (90 %: "
        f"{q[0]:.4g} .. {q[2]:.4g}; prior uniform on [{lo:g}, {hi:g}]); the true px/mm is "
        f"{math.sqrt(q[1]):.3g} x the assumed one"
    )
    edge = AREA_SCALE_EDGE * (hi - lo)
    if q[0] - lo < edge or hi - q[2] < edge:
        side = f"lower bound {lo:g}" if q[0] - lo < edge else f"upper bound {hi:g}"
        out["warning"] = (
            f"AREA SCALE AT BOUND: the area scale k piles against the {side} of its prior (90 %: "
            f"{q[0]:.4g} .. {q[2]:.4g}); widen --area-scale, or the model cannot open as wide (or "
            "as narrow) as the recording at any parameters the prior allows"
        )
    return out


def reach_of(spec: JobSpec) -> dict | None:
    """The reach check of the job's recording (``JobSpec.reach``) as a dict, ``None`` for a model other than "fe"; an
    error is reported, not raised."""
    if spec.model != "fe":
        return None
    try:
        return spec.reach().to_dict()
    except Exception as exc:  # noqa: BLE001 - a check must not fail the job; recorded
        return {"verdict": "unchecked", "message": f"reach check failed: {type(exc).__name__}: {exc}"}


def edge_warnings(spec: JobSpec, post, nc: dict | None) -> list[str]:
    """Plain warnings for a posterior at the edges (:ref:`inference`, "The model's reach"): each parameter
    piled against a bound of the prior's box (:func:`vfcore.inference.identify.at_bounds`), and a residual
    RMS more than ``MISFIT_RATIO_WARN`` times the recording's own noise sd (``nc``: :func:`noise_check`)."""
    from vfcore.inference.identify import at_bounds

    out = [r["warning"] for r in at_bounds(post, spec.to_prior())]
    if nc is not None and nc.get("misfit_ratio") is not None and nc["misfit_ratio"] > MISFIT_RATIO_WARN:
        r, s = nc["residual_rms"]["q50"], nc["recording_noise_sd"]
        out.append(
            f"MISFIT: the fit's residual RMS is {r:.3g} mm^2, {r / s:.1f} times the recording's noise "
            f"({s:.3g} mm^2, estimated from second differences of the residual): the model does not "
            "reproduce this recording, and the posterior describes the closest the prior lets it come, "
            "not the fold; check the recording against the model's reach (docs/inference.md, "
            '"The model\'s reach")'
        )
    return out


def publish_posterior(store_path: str, post, spec: JobSpec | None = None) -> dict:
    """Write the posterior arrays, summary, CSV and figures into the store; return the summary. ``spec``: the
    job's, when the caller has parsed it (its Problem is then shared by every check); else read from the store."""
    root = st.open_store(Path(store_path))
    if spec is None:
        spec = JobSpec.model_validate(dict(root.attrs["jobspec"]))
    if spec.model == "fe":
        post.model = model_record(spec.to_problem())
    resampled = post.resampled_predictive()
    scale = area_scale_of(spec, resampled)
    if scale is not None and scale.get("warning"):
        post.warnings = list(post.warnings) + [scale["warning"]]
    reg = regularity_of(spec, post)
    w = regularity_warning(reg)
    if w:
        post.warnings = list(post.warnings) + [w]
    w = runs_warning(spec)
    if w:
        post.warnings = list(post.warnings) + [w]
    ident = identifiability_of(spec, post)
    if ident is not None and ident.get("warnings"):
        post.warnings = list(post.warnings) + list(ident["warnings"])
    nc = noise_check(spec, post, resampled)
    if nc is not None and nc["noise"] == "fixed" and not (1 / NOISE_RATIO_WARN <= nc["ratio"] <= NOISE_RATIO_WARN):
        r, se = nc["residual_rms"]["q50"], nc["sigma_e"]
        how = f"about {r / se:.1f} times too narrow" if r > se else f"about {se / r:.1f} times too wide"
        post.warnings = list(post.warnings) + [
            f"NOISE LEVEL: the fit's residual RMS is {r:.3g} mm^2 against sigma_e = {se:g} mm^2; if the misfit is "
            f"noise, the posterior is {how}; set sigma_e to the recording's noise or use noise='marginal' "
            "(docs/inference.md, 'Unknown noise level')"
        ]
    reach = reach_of(spec)
    if reach is not None and reach.get("verdict") in ("outside", "marginal"):
        post.warnings = list(post.warnings) + [f"REACH: {reach['message']}"]
    try:
        post.warnings = list(post.warnings) + edge_warnings(spec, post, nc)
    except Exception as exc:  # noqa: BLE001 - a check must not fail the job; recorded
        post.warnings = list(post.warnings) + [f"edge check failed: {type(exc).__name__}: {exc}"]
    pred, bands = _predictive_summary(resampled, spec.contact)
    summary = posterior_summary(post, pred)
    summary["model"] = {
        "name": spec.model,
        "mesh": spec.mesh,
        "dt": spec.dt,
        "duration": spec.duration,
        "discard": spec.discard,
        "contact": spec.contact,
    }
    if spec.contact == "layer":
        summary["model"]["contact_layer_mm"] = spec.contact_layer_mm
    if scale is not None:
        summary["area_scale"] = jsonable(scale)
        summary["formatted"] = summary["formatted"] + "\n" + scale["formatted"]
    if reg is not None:
        summary["regularity"] = jsonable(reg)
    if nc is not None:
        summary["noise_check"] = jsonable(nc)
    if ident is not None:
        summary["identifiability"] = jsonable(ident)
    if reach is not None:
        summary["reach"] = jsonable(reach)
    pg = root.require_group("posterior")
    for name, arr in (
        ("samples", np.asarray(post.samples, dtype=float)),
        ("log_weights", np.asarray(post.log_weights, dtype=float)),
        ("resampled", np.asarray(post.resampled, dtype=np.int64)),
    ):
        a = pg.create_array(name, shape=arr.shape, chunks=arr.shape or (1,), dtype=arr.dtype, overwrite=True)
        a[...] = arr
    if bands is not None:
        a = pg.create_array("gaw_bands", shape=bands.shape, chunks=bands.shape, dtype="float64", overwrite=True)
        a[...] = bands
    csv_bytes, meta = samples_csv(post)
    st.write_blob(root, "samples_csv", csv_bytes)
    st.write_blob(root, "samples_meta", meta)
    try:
        st.write_blob(root, "posterior_nc", netcdf_bytes(post))
    except Exception as exc:  # noqa: BLE001 - an export must not fail the job; recorded
        summary["export_errors"] = {"posterior_nc": f"{type(exc).__name__}: {exc}"}
    from .figures import fig_contact, fig_corner, fig_gaw_fit

    noise_sd = None if nc is None else (nc["sigma_e"] if nc["noise"] == "fixed" else nc["residual_rms"]["q50"])
    for name, fn in (
        ("gaw_fit", lambda p, b: fig_gaw_fit(p, b, noise_sd, pred=resampled)),
        ("corner", fig_corner),
        ("contact_pressure", fig_contact),
    ):
        try:
            st.write_blob(root, name, fn(post, bands))
        except Exception as exc:  # noqa: BLE001 - a figure must not fail the job; recorded
            summary.setdefault("figure_errors", {})[name] = f"{type(exc).__name__}: {exc}"
    pg.attrs["summary"] = summary  # written last: its presence means "posterior published"
    return summary


# ---------------------------------------------------------------------------------------- data files
def samples_csv(post) -> tuple[bytes, bytes]:
    """All weighted draws as plain CSV (header row, then one row per draw: the parameters in paper units,
    ``log_weight``, ``weight`` and ``n_resampled``, the times the draw occurs in the resampled ensemble),
    and its metadata as a JSON sidecar (names, units, columns, diagnostics; non-finite numbers as null):
    any CSV reader takes the file as it is."""
    import csv
    import json

    counts = np.bincount(np.asarray(post.resampled, dtype=np.int64), minlength=post.samples.shape[0])
    w = post.weights
    buf = io.StringIO()
    wr = csv.writer(buf, lineterminator="\n")
    wr.writerow(list(post.names) + ["log_weight", "weight", "n_resampled"])
    for i in range(post.samples.shape[0]):
        lw = float(post.log_weights[i])
        wr.writerow(
            [repr(float(v)) for v in post.samples[i]]
            + [repr(lw) if math.isfinite(lw) else "", repr(float(w[i])), int(counts[i])]
        )
    meta = jsonable(
        {
            "format": "vfinfer samples v2",
            "names": list(post.names),
            "units": {n: PARAM_UNITS[n] for n in post.names},
            "columns": {
                "log_weight": "normalised log importance weight (empty: weight 0)",
                "weight": "normalised weight",
                "n_resampled": "copies in the resampled ensemble",
            },
            "method": post.method,
            "ess": post.ess,
            "pareto_k": post.pareto_k,
            "log_evidence": post.log_evidence,
            "log_evidence_se": post.log_evidence_se,
            "n_simulations": post.n_simulations,
            "n_failed": post.n_failed,
            "warnings": list(post.warnings),
            "fps": post.fps,
        }
    )
    return buf.getvalue().encode(), json.dumps(meta, indent=1, sort_keys=True).encode()


def netcdf_bytes(post) -> bytes:
    """The posterior as ArviZ InferenceData in NetCDF-4 (``Posterior.to_inference_data``: posterior, weighted
    samples, observed GAW and posterior predictive where available)."""
    fd, tmp = tempfile.mkstemp(suffix=".nc")
    os.close(fd)
    try:
        post.to_netcdf(tmp)
        return Path(tmp).read_bytes()
    finally:
        os.unlink(tmp)


# ---------------------------------------------------------------------------------------- compare
def compare_posteriors(named_paths: dict[str, Path]) -> dict:
    """Pairwise Welch t-tests of the resampled ensembles, per common parameter."""
    from scipy import stats

    ens = {}
    for jid, path in named_paths.items():
        arr = st.read_posterior_arrays(path)
        summ = st.read_summary(path) or {}
        ens[jid] = (list(summ.get("names", [])), arr["samples"][arr["resampled"]])
    ids = list(ens)
    out = []
    for a in range(len(ids)):
        for b in range(a + 1, len(ids)):
            na, xa = ens[ids[a]]
            nb, xb = ens[ids[b]]
            for name in [n for n in na if n in nb]:
                va, vb = xa[:, na.index(name)], xb[:, nb.index(name)]
                t, p = stats.ttest_ind(va, vb, equal_var=False)
                out.append(
                    {
                        "job_a": ids[a],
                        "job_b": ids[b],
                        "parameter": name,
                        "mean_a": float(va.mean()),
                        "mean_b": float(vb.mean()),
                        "t": float(t),
                        "p_value": float(p),
                    }
                )
    return jsonable({"tests": out, "method": "Welch two-sample t-test on resampled posterior ensembles"})
