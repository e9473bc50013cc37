"""Diagnosis of a finished job: ``POST /jobs/{id}/diagnose`` queues a diagnosis job (run by the job manager like
an inference, :mod:`service.diagnosis`); ``GET /jobs/{id}/diagnosis`` and ``GET /jobs/{id}/diagnosis/figure`` read
it; ``GET /jobs/{id}/diagnosis/report`` shows it as an HTML page (bearer token, or a signed link from
``POST /jobs/{id}/diagnosis/report-link``); ``DELETE /jobs/{id}/diagnosis`` cancels it, as
``DELETE /jobs/{diagnosis_id}`` does.

Ownership rules are those of the other job endpoints (another user's job answers 404). One diagnosis per job at
a time; a new one replaces the previous one.
"""

from __future__ import annotations

from fastapi import APIRouter, Body, HTTPException, Request, Response, status
from fastapi.responses import HTMLResponse

from worker import store as st

from ..access import done_job, own_job, page_reader
from ..api_models import DiagnoseRequest, DiagnoseStarted, DiagnosisSpec, DiagnosisStatus, ExpectedDiagnosis, LinkOut
from ..db import ACTIVE
from ..deps import JobIdDep, ManagerDep, UserDep
from ..diagnosis import expected, read_report
from ..manager import DiagnosisRunning
from ..signing import Exp, OptionalUserDep, Sig, SignerDep, link_out

router = APIRouter(tags=["diagnosis"])


def _latest(manager, job_id: str) -> dict | None:
    """The job's diagnosis (its newest: a new one replaces the previous one)."""
    rows = manager.db.children(job_id)
    return rows[0] if rows else None


def _finished(manager, job_id: str, user: str) -> dict:
    """The row of ``user``'s job's finished diagnosis; 404 otherwise."""
    diag = _latest(manager, own_job(manager, job_id, user)["id"])
    if diag is None or diag["state"] != "done":
        raise HTTPException(status.HTTP_404_NOT_FOUND, "no finished diagnosis of this job")
    return diag


def diagnosis_report_scope(job_id: str) -> str:
    """The signed-link scope of a job's diagnosis page: another page than the job's report, so a link to one
    never opens the other."""
    return f"diagnosis-report/{job_id}"


@router.post(
    "/jobs/{job_id}/diagnose",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=DiagnoseStarted,
    summary="Start a diagnosis of a finished job: which physics is the model missing?",
)
def start_diagnosis(
    job_id: JobIdDep, user: UserDep, manager: ManagerDep, req: DiagnoseRequest | None = Body(default=None)
) -> DiagnoseStarted:
    rec = done_job(manager, job_id, user)
    if rec["model"] != "fe":
        raise HTTPException(
            422,
            [
                {
                    "loc": ["path", "job_id"],
                    "type": "value_error",
                    "msg": f"diagnosis needs a job of the finite-element model ('fe'), this one is {rec['model']!r}",
                }
            ],
        )
    req = req or DiagnoseRequest()
    c = expected(rec["spec"], manager.store_path(rec["id"]), req)
    try:
        diag_id = manager.submit_diagnosis(user, rec["id"], req)
    except DiagnosisRunning:
        raise HTTPException(status.HTTP_409_CONFLICT, "a diagnosis of this job is already running") from None
    cost = ExpectedDiagnosis(
        floor_simulations=c.floor, catalogue_simulations=c.catalogue, base_fits=c.base_fits, scaled_for=list(c.guide)
    )
    return DiagnoseStarted(
        id=rec["id"], state="queued", status_url=f"/jobs/{rec['id']}/diagnosis", diagnosis_id=diag_id, expected=cost
    )


@router.get(
    "/jobs/{job_id}/diagnosis",
    response_model=DiagnosisStatus,
    summary="A diagnosis's state, current stage and, when done, its report",
)
def get_diagnosis(job_id: JobIdDep, user: UserDep, manager: ManagerDep, request: Request) -> DiagnosisStatus:
    # ``request`` is unused here; the jobs page calls this handler with it, to show what the API answers
    diag = _latest(manager, own_job(manager, job_id, user)["id"])
    if diag is None:
        return DiagnosisStatus(state="none")
    live = manager.live(diag["id"]) if diag["state"] == "running" else None
    report = None
    if diag["state"] == "done":
        report = read_report(manager.store_path(diag["id"]), diag["stats"], _request(diag))
    return DiagnosisStatus(
        state=diag["state"],
        error=diag["error"],
        report=report,
        progress=live.event if live is not None else None,
        diagnosis_id=diag["id"],
    )


def _request(diag: dict) -> dict:
    """The settings a diagnosis ran with (its report carries them)."""
    return DiagnosisSpec.model_validate_json(diag["spec"]).request.model_dump()


@router.delete("/jobs/{job_id}/diagnosis", status_code=status.HTTP_202_ACCEPTED, summary="Cancel a running diagnosis")
def cancel_diagnosis(job_id: JobIdDep, user: UserDep, manager: ManagerDep) -> dict:
    """Cancel a queued or running diagnosis (as ``DELETE /jobs/{diagnosis_id}``): it stops within a quarter of a
    second of waiting on the cluster (its batch's unstarted simulations are cancelled), its stored simulations
    are deleted and its state becomes "cancelled"."""
    jid = own_job(manager, job_id, user)["id"]
    diag = _latest(manager, jid)
    if diag is None or diag["state"] not in ACTIVE or not manager.cancel(diag["id"]):
        raise HTTPException(status.HTTP_409_CONFLICT, "no diagnosis of this job is running")
    return {"id": jid, "state": "cancelling", "status_url": f"/jobs/{jid}/diagnosis", "diagnosis_id": diag["id"]}


@router.get(
    "/jobs/{job_id}/diagnosis/figure",
    responses={200: {"content": {"image/png": {}}}},
    summary="A finished diagnosis's figure (PNG): base fit, located mismatch, named extension",
)
def get_diagnosis_figure(job_id: JobIdDep, user: UserDep, manager: ManagerDep) -> Response:
    diag = _finished(manager, job_id, user)
    png = st.read_blob(manager.store_path(diag["id"]), "diagnosis_png")
    if png is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, "diagnosis figure not available")
    return Response(png, media_type="image/png")


@router.get(
    "/jobs/{job_id}/diagnosis/report",
    response_class=HTMLResponse,
    summary="A finished diagnosis as one self-contained HTML page (figure embedded): verdict, located "
    "mismatch, ranked catalogue entries, cost; opens with the bearer token or with a signed link "
    "from POST /jobs/{id}/diagnosis/report-link",
    responses={
        401: {"description": "neither a bearer token nor a signed link"},
        403: {"description": "a signed link that is expired, altered or made for another page"},
        404: {"description": "no such job of yours, or no finished diagnosis of it"},
    },
)
def get_diagnosis_report(
    job_id: JobIdDep, manager: ManagerDep, signer: SignerDep, user: OptionalUserDep, exp: Exp = None, sig: Sig = None
) -> HTMLResponse:
    from ..report import PAGE_HEADERS, data_uri
    from ..report_diagnose import render_diagnosis_report

    user = page_reader(
        manager, job_id, user, signer, diagnosis_report_scope(job_id), exp, sig, "POST /jobs/{id}/diagnosis/report-link"
    )
    diag = _finished(manager, job_id, user)
    path = manager.store_path(diag["id"])
    d = read_report(path, diag["stats"], _request(diag))
    png = st.read_blob(path, "diagnosis_png")
    fig = data_uri(png) if png is not None else None
    jid = diag["parent"]
    return HTMLResponse(
        render_diagnosis_report(d, fig, f"vfinfer diagnosis of job {jid}", source={"job": jid}), headers=PAGE_HEADERS
    )


@router.post(
    "/jobs/{job_id}/diagnosis/report-link",
    response_model=LinkOut,
    summary="A short-lived signed link to a finished diagnosis's HTML page that a browser opens without "
    "the bearer token",
)
def diagnosis_report_link(
    job_id: JobIdDep, user: UserDep, manager: ManagerDep, signer: SignerDep, request: Request
) -> LinkOut:
    jid = _finished(manager, job_id, user)["parent"]
    return link_out(request, signer.sign(diagnosis_report_scope(jid), f"/jobs/{jid}/diagnosis/report"))
