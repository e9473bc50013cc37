"""Job endpoints. A user only ever sees their own jobs: any other id answers 404 (existence is not
revealed).  Paths into the data directory are built from table rows, never from request text."""

from __future__ import annotations

import time
from typing import Annotated, Literal

import numpy as np
from fastapi import APIRouter, HTTPException, Query, Request, Response, status
from fastapi.responses import HTMLResponse, JSONResponse

from worker import store as st
from worker.models import model_named
from worker.reduce import compare_posteriors
from worker.run import expected_simulations

from ..access import done_job, own_job, page_reader
from ..api_models import CompareRequest, Figure, JobSpec, JobStatus, LinkOut, Submitted
from ..db import ACTIVE
from ..deps import JOB_ID_RE, JobIdDep, ManagerDep, SettingsDep, UserDep
from ..signing import Exp, OptionalUserDep, Sig, SignerDep, link_out, report_scope

router = APIRouter(tags=["jobs"])


def _status(manager, rec: dict) -> JobStatus:
    """A job's status from its table row and, while it runs, the manager's memory: no spec is parsed."""
    lv = manager.live(rec["id"]) if rec["state"] == "running" else None
    n_done, n_total, ess, phase = rec["n_done"], rec["n_total"], rec["ess"], rec["state"]
    if lv is not None:
        p = lv.progress
        n_done, n_total, phase = p.n_done, max(p.n_total, p.n_done), p.phase
        ess = p.ess if p.ess == p.ess else None
    now = time.time()
    timings = {
        "created": rec["created"],
        "started": rec["started"],
        "finished": rec["finished"],
        "queued_s": ((rec["started"] or now) - rec["created"]),
        "running_s": (((rec["finished"] or now) - rec["started"]) if rec["started"] else None),
    }
    progress = {
        "simulations_done": n_done,
        "simulations_total": n_total,
        "fraction": (n_done / n_total) if n_total else 0.0,
        "phase": phase,
    }
    if rec["kind"] == "diagnosis" and rec["state"] != "done":
        # a diagnosis's simulations are known only once it ends: which stages run depends on the data
        progress.update(simulations_total=None, fraction=None)
    return JobStatus(
        id=rec["id"],
        state=rec["state"],
        ess=ess,
        timings=timings,
        error=rec["error"],
        progress=progress,
        sampler=rec["sampler"] or "?",
        model=rec["model"] or "?",
        stats=rec["stats"] or {},
        warnings=list((rec["stats"] or {}).get("warnings", [])),
        kind=rec["kind"],
        parent=rec["parent"],
    )


def reach_gate(spec: JobSpec) -> tuple[JSONResponse | None, dict]:
    """The reach check at submission (:ref:`inference`, "The model's reach"): a 422 response for a recording
    outside the reach unless ``force_reach``, else the notes to store with the job (its warnings). Where no
    ensemble matches, none is built here (minutes): the job goes on with a warning saying how to build one."""
    v = spec.reach()
    if v.verdict == "outside" and not spec.force_reach:
        return JSONResponse(
            status_code=422,
            content={
                "detail": [
                    {
                        "loc": ["body", "gaw"],
                        "type": "value_error",
                        "msg": v.message + "; send force_reach: true to fit anyway",
                        "reach": v.to_dict(),
                    }
                ]
            },
        ), {}
    w = v.warning("force_reach")
    warnings = [f"REACH: {w}"] if w is not None and spec.model == "fe" else []  # only the FE model has a reach
    return None, {"reach": v.to_dict(), "warnings": warnings}


@router.post(
    "/jobs",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=Submitted,
    summary="Submit an inference job (a GAW and the sampler's settings); answers its id",
)
def submit(spec: JobSpec, user: UserDep, manager: ManagerDep, settings: SettingsDep) -> Submitted:
    if model_named(spec.model).test_double and not settings.allow_toy_model:
        return JSONResponse(
            status_code=422,
            content={
                "detail": [
                    {
                        "loc": ["body", "model"],
                        "type": "value_error",
                        "msg": f"model {spec.model!r} is a test double and is disabled on this service",
                    }
                ]
            },
        )
    if manager.db.count_active(user) >= settings.max_active_jobs_per_user:
        raise HTTPException(
            status.HTTP_429_TOO_MANY_REQUESTS,
            f"at most {settings.max_active_jobs_per_user} queued/running jobs per user",
        )
    refused, notes = reach_gate(spec)
    if refused is not None:
        return refused
    job_id = manager.submit(user, spec, notes=notes)
    return Submitted(
        id=job_id,
        state="queued",
        status_url=f"/jobs/{job_id}",
        warnings=notes.get("warnings", []),
        expected_simulations=expected_simulations(spec),
    )


@router.get("/jobs", response_model=list[JobStatus], summary="List your jobs with their state and progress")
def list_jobs(user: UserDep, manager: ManagerDep) -> list[JobStatus]:
    return [_status(manager, r) for r in manager.db.list(owner=user)]


@router.get(
    "/jobs/{job_id}",
    response_model=JobStatus,
    summary="A job's state, progress (simulations done), ESS, times (epoch s) and warnings; an inference "
    "or a diagnosis (the diagnosis_id of POST /jobs/{id}/diagnose)",
)
def get_job(job_id: JobIdDep, user: UserDep, manager: ManagerDep) -> JobStatus:
    return _status(manager, own_job(manager, job_id, user, kind=None))


@router.get(
    "/jobs/{job_id}/posterior",
    summary="A finished job's posterior summary: table (paper units), predictive, diagnostics, warnings",
)
def get_posterior(job_id: JobIdDep, user: UserDep, manager: ManagerDep) -> dict:
    rec = done_job(manager, job_id, user)
    summary = st.read_summary(manager.store_path(rec["id"]))
    if summary is None:
        raise HTTPException(status.HTTP_500_INTERNAL_SERVER_ERROR, "posterior missing from the store")
    return {"id": rec["id"], **summary}


#: ``?format=`` of /samples: store product, media type, file suffix
SAMPLE_FORMATS = {
    "csv": ("samples_csv", "text/csv", ".csv"),
    "meta": ("samples_meta", "application/json", ".json"),
    "netcdf": ("posterior_nc", "application/x-netcdf", ".nc"),
}


@router.get(
    "/jobs/{job_id}/samples",
    summary="A finished job's weighted draws: plain CSV, its JSON metadata, NetCDF (ArviZ) or JSON arrays",
    responses={200: {"content": {"text/csv": {}, "application/json": {}, "application/x-netcdf": {}}}},
)
def get_samples(
    job_id: JobIdDep,
    user: UserDep,
    manager: ManagerDep,
    format: Annotated[
        Literal["csv", "meta", "netcdf", "json"],
        Query(
            description="csv: one row per weighted draw (parameters in paper units, log_weight, weight, "
            "n_resampled); meta: the CSV's metadata (names, units, diagnostics); netcdf: ArviZ "
            "InferenceData with the observed GAW and the posterior predictive; json: arrays"
        ),
    ] = "csv",
) -> Response:
    rec = done_job(manager, job_id, user)
    path = manager.store_path(rec["id"])
    if format in SAMPLE_FORMATS:
        product, media, suffix = SAMPLE_FORMATS[format]
        blob = st.read_blob(path, product)
        if blob is None:
            raise HTTPException(
                status.HTTP_404_NOT_FOUND, f"no {format} export in this job's store (made by an older release)"
            )
        return Response(
            blob, media_type=media, headers={"Content-Disposition": f'attachment; filename="{rec["id"]}{suffix}"'}
        )
    arr = st.read_posterior_arrays(path)
    summ = st.read_summary(path) or {}
    lw = arr["log_weights"]
    return JSONResponse(
        {
            "names": summ.get("names"),
            "samples": arr["samples"].tolist(),
            "log_weights": [float(x) if np.isfinite(x) else None for x in lw],
            "resampled": arr["resampled"].tolist(),
        }
    )


@router.get(
    "/jobs/{job_id}/figures/{name}",
    responses={200: {"content": {"image/png": {}}}},
    summary="A finished job's figure (PNG): GAW fit with predictive bands, pair plot, flow and contact",
)
def get_figure(job_id: JobIdDep, name: Figure, user: UserDep, manager: ManagerDep) -> Response:
    rec = done_job(manager, job_id, user)
    blob = st.read_blob(manager.store_path(rec["id"]), name.value)
    if blob is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, "figure not available")
    return Response(blob, media_type="image/png")


@router.get(
    "/jobs/{job_id}/report",
    response_class=HTMLResponse,
    summary="A finished job's report as one self-contained HTML page (figures embedded); opens with the "
    "bearer token or with a signed link from POST /jobs/{id}/report-link",
    responses={
        401: {"description": "neither a bearer token nor a signed link"},
        403: {"description": "a signed link that is expired, altered or made for another page"},
    },
)
def get_report(
    job_id: JobIdDep, manager: ManagerDep, signer: SignerDep, user: OptionalUserDep, exp: Exp = None, sig: Sig = None
) -> HTMLResponse:
    from ..report import FIGURES, PAGE_HEADERS, data_uri, render_report

    user = page_reader(
        manager,
        job_id,
        user,
        signer,
        report_scope(job_id),
        exp,
        sig,
        "POST /jobs/{id}/report-link, or 'vfinfer report ID',",
    )
    rec = done_job(manager, job_id, user)
    path = manager.store_path(rec["id"])
    summary = st.read_summary(path)
    if summary is None:
        raise HTTPException(status.HTTP_500_INTERNAL_SERVER_ERROR, "posterior missing from the store")
    images = {n: data_uri(b) for n in FIGURES if (b := st.read_blob(path, n)) is not None}
    timings = {
        "queued_s": (rec["started"] or rec["created"]) - rec["created"],
        "running_s": ((rec["finished"] or time.time()) - rec["started"]) if rec["started"] else None,
    }
    return HTMLResponse(
        render_report(summary, images, f"vfinfer job {rec['id']}", timings=timings), headers=PAGE_HEADERS
    )


@router.post(
    "/jobs/{job_id}/report-link",
    response_model=LinkOut,
    summary="A short-lived signed link to a finished job's HTML report that a browser opens without the bearer token",
)
def report_link(job_id: JobIdDep, user: UserDep, manager: ManagerDep, signer: SignerDep, request: Request) -> LinkOut:
    rec = done_job(manager, job_id, user)
    return link_out(request, signer.sign(report_scope(rec["id"]), f"/jobs/{rec['id']}/report"))


@router.delete(
    "/jobs/{job_id}",
    summary="Cancel a queued or running job, an inference or a diagnosis (a finished job keeps its state)",
)
def cancel_job(job_id: JobIdDep, user: UserDep, manager: ManagerDep) -> dict:
    rec = own_job(manager, job_id, user, kind=None)
    if rec["state"] in ACTIVE:
        manager.cancel(rec["id"])
    return {"id": rec["id"], "state": manager.db.get(rec["id"])["state"]}


@router.post("/compare", summary="Compare finished jobs' posteriors parameter by parameter (Welch t-tests)")
def compare(req: CompareRequest, user: UserDep, manager: ManagerDep) -> dict:
    ids = list(dict.fromkeys(req.job_ids))
    if len(ids) < 2:
        raise HTTPException(
            422, [{"loc": ["body", "job_ids"], "msg": "need two distinct job ids", "type": "value_error"}]
        )
    paths = {}
    for jid in ids:
        if not JOB_ID_RE.match(jid):
            raise HTTPException(status.HTTP_404_NOT_FOUND, "job not found")
        rec = done_job(manager, jid, user)
        paths[rec["id"]] = manager.store_path(rec["id"])
    return compare_posteriors(paths)
