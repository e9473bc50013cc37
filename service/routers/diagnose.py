"""Model diagnosis of a finished job: ``POST /jobs/{id}/diagnose`` starts
:func:`vfcore.diagnose.pipeline.diagnose` on the job's problem in a background thread (its
simulations run on the service's Dask cluster); ``GET /jobs/{id}/diagnosis`` and
``GET /jobs/{id}/diagnosis/figure`` read the result; ``GET /jobs/{id}/diagnosis/report`` shows it as an HTML
page (bearer token, or a signed link from ``POST /jobs/{id}/diagnosis/report-link``).

Ownership rules are those of the other job endpoints (another user's job answers 404).  The
result lies next to the job's store (``<id>.diagnosis.json`` / ``.png``; a failure leaves
``<id>.diagnosis.error``), each written to a temporary file and renamed, so a half-written result
is never served.  One diagnosis per job at a time.

A diagnosis outlives a restart of the service: its request is kept in
``<id>.diagnosis.request.json`` until it ends, and at the next start (:func:`on_startup`) every
diagnosis that a shutdown or a crash interrupted is started again with the same request, reading
its finished simulations back from ``<id>.diagnosis.resume`` (at most ``MAX_AUTO_RESUMES`` times,
so a diagnosis that brings the service down cannot do so forever).  A diagnosis that fails on its
own is recorded as failed and is not started again.
"""
from __future__ import annotations

import json
import logging
import math
import os
import secrets
import shutil
import threading
from pathlib import Path

import numpy as np
from fastapi import APIRouter, Body, HTTPException, Request, Response, status
from fastapi.responses import HTMLResponse
from pydantic import BaseModel, ConfigDict, Field, field_validator

from vfcore.diagnose.defaults import BASE_PARTICLES, CONTINUATION, MAX_REFITS, REFIT_PARTICLES
from worker.jobspec import JobSpec

from ..access import done_job, own_job, page_reader
from ..deps import JobIdDep, ManagerDep, UserDep
from ..signing import Exp, LinkOut, OptionalUserDep, Sig, SignerDep, link_out

log = logging.getLogger("vfinfer.diagnose")

router = APIRouter(tags=["diagnosis"])

#: matplotlib's pyplot is not thread-safe: one figure at a time in this process.
_PLOT_LOCK = threading.Lock()
_REG_LOCK = threading.Lock()


# ------------------------------------------------------------------------------------ helpers
def jsonable(obj):
    """A strict-JSON copy of a report: numpy scalars/arrays to Python, non-finite floats to None."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return x if math.isfinite(x) else None
    if obj is None or isinstance(obj, str):
        return obj
    return str(obj)


def check_candidates(names) -> list[str]:
    """Unknown or not-implemented extension names raise ValueError naming them."""
    from vfcore.diagnose.extensions import CATALOGUE
    names = list(dict.fromkeys(n.strip() for n in names))
    unknown = [n for n in names if n not in CATALOGUE]
    if unknown:
        raise ValueError(f"unknown candidate(s) {unknown}; known: {sorted(CATALOGUE)}")
    unimpl = [n for n in names if not CATALOGUE[n].implemented]
    if unimpl:
        impl = sorted(n for n, e in CATALOGUE.items() if e.implemented)
        raise ValueError(f"candidate(s) {unimpl} are catalogued but not implemented; fittable: {impl}")
    if not names:
        raise ValueError("no candidates given")
    return names


def write_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(6)}.tmp")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def plot_atomic(report, problem, path: Path) -> None:
    from vfcore.diagnose.pipeline import plot_diagnosis
    tmp = path.with_name(f".{path.stem}.{secrets.token_hex(6)}.tmp.png")
    try:
        with _PLOT_LOCK:
            plot_diagnosis(report, problem, tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


#: how often (s) a map waiting on a running simulation looks whether it was cancelled
POLL_S = 0.25


def dask_map(client, stop: threading.Event | None = None, stopping: threading.Event | None = None):
    """A builtin-map-like callable running every call on the Dask cluster.

    Results come back in order, each as soon as it and those before it are done, so the
    diagnosis' store (:class:`vfcore.inference.memo.CachedMap`) keeps every finished part of a
    batch that is later interrupted. While it waits it looks every ``POLL_S`` seconds at
    ``stop`` (set by a cancel: :class:`DiagnosisCancelled`) and ``stopping`` (set when the
    service shuts down: ``DiagnosisInterrupted``); either cancels the batch's unfinished futures,
    so a cancel takes effect within a poll, not after the batch in flight."""
    if client is None:
        return map

    def _check():
        if stop is not None and stop.is_set():
            raise DiagnosisCancelled("cancelled")
        if stopping is not None and stopping.is_set():
            raise DiagnosisInterrupted("the service is stopping")

    def _map(fn, xs):
        futures = client.map(fn, list(xs), pure=False)
        try:
            for fut in futures:
                # Wait on a local event, not on fut.result(timeout=...): in distributed 2026.8 a
                # result() whose timeout races the result's arrival can end in UnboundLocalError
                # (its sync() lets a CancelledError of the timed-out wait through), seen under load.
                done = threading.Event()
                fut.add_done_callback(lambda _f, done=done: done.set())
                _check()
                while not done.wait(POLL_S):
                    _check()
                yield fut.result()
        finally:                      # stopped early, failed or cancelled: drop what is left
            left = [f for f in futures if not f.done()]
            if left:
                client.cancel(left)
    return _map


def _n_workers(client) -> int:
    if client is None:
        return 1
    try:
        return max(1, len(client.scheduler_info()["workers"]))
    except Exception:  # noqa: BLE001 - only used to size chunks
        return 1


# ------------------------------------------------------------------------------------ state
class _Registry:
    """Diagnoses running in this process (job id -> thread); results live on disk."""

    def __init__(self):
        self.lock = threading.Lock()
        self.running: dict[str, threading.Thread] = {}
        self.progress: dict[str, dict] = {}     # job id -> latest vfcore.diagnose.progress event
        self.stopping = threading.Event()        # set at shutdown: failures from then on are interruptions
        self.cancel: dict[str, threading.Event] = {}   # job id -> set by DELETE /jobs/{id}/diagnosis


class DiagnosisCancelled(Exception):
    """Raised inside a running diagnosis once it is cancelled (within a poll, :func:`dask_map`)."""


class DiagnosisInterrupted(Exception):
    """Raised inside a running diagnosis when the service stops; it resumes at the next start."""


def cancellable(inner, event: threading.Event):
    """``map`` that refuses to start, or to return, a batch once ``event`` is set."""
    def _map(fn, parts):
        if event.is_set():
            raise DiagnosisCancelled("cancelled")
        out = list(inner(fn, parts))
        if event.is_set():
            raise DiagnosisCancelled("cancelled")
        return out
    _map.inner = inner
    return _map


def _registry(request: Request) -> _Registry:
    st = request.app.state
    with _REG_LOCK:
        reg = getattr(st, "diagnoses", None)
        if reg is None:
            reg = st.diagnoses = _Registry()
    return reg


#: automatic restarts of one interrupted diagnosis before it is recorded as failed
MAX_AUTO_RESUMES = 3


def _stores_dir(manager) -> Path:
    """The folder holding every job's store and its diagnosis files."""
    return Path(manager.settings.stores_dir)


def _request_path(manager, job_id: str) -> Path:
    return _stores_dir(manager) / f"{job_id}.diagnosis.request.json"


def _cancelled_path(manager, job_id: str) -> Path:
    return _stores_dir(manager) / f"{job_id}.diagnosis.cancelled"


def _paths(manager, job_id: str) -> tuple[Path, Path, Path]:
    # job_id comes from the table row (see own_job), never from request text
    base = _stores_dir(manager)
    return (base / f"{job_id}.diagnosis.json", base / f"{job_id}.diagnosis.png",
            base / f"{job_id}.diagnosis.error")


# ------------------------------------------------------------------------------------ models
class DiagnoseRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")

    candidates: list[str] | None = Field(
        default=None, min_length=1, max_length=50,
        description="catalogued, implemented extensions to screen (default: all implemented ones)")
    n_particles: int = Field(default=BASE_PARTICLES, ge=10, le=400, description="SMC particles of each base fit")
    refit_particles: int = Field(default=REFIT_PARTICLES, ge=4, le=400, description="SMC particles of each extended fit")
    max_refits: int | None = Field(default=MAX_REFITS, ge=0, le=6,
                                   description="most observation-level extensions refitted, best screened "
                                               "first (default: all six)")
    continuation: bool = Field(default=CONTINUATION,
                               description="also search the base model and every extension by window "
                                           "continuation and fit from the optimum (docs/diagnose.md section 4)")
    seed: int = Field(default=0, ge=0, lt=2**63)

    @field_validator("candidates")
    @classmethod
    def _known(cls, v):
        return None if v is None else check_candidates(v)


class DiagnoseStarted(BaseModel):
    id: str
    state: str
    status_url: str


class DiagnosisStatus(BaseModel):
    state: str = Field(description='"none", "running", "done", "failed" or "cancelled"')
    error: str | None = None
    report: dict | None = None
    progress: dict | None = Field(default=None, description=(
        "while running: the stage, the catalogue entry, its place (step of steps), the simulations "
        "evaluated so far and the seconds elapsed (vfcore.diagnose.progress)"))


# ------------------------------------------------------------------------------------ worker
def resume_store(manager, job_id: str) -> Path:
    """Where a running diagnosis keeps its finished simulations (vfcore.inference.memo.CachedMap):
    started again after an interruption, the same request reads them back."""
    return manager.store_path(job_id).parent / f"{job_id}.diagnosis.resume"


def _run(manager, reg: _Registry, job_id: str, spec: JobSpec, req: DiagnoseRequest) -> None:
    from vfcore.diagnose.pipeline import diagnose
    from vfcore.inference.memo import CachedMap, account
    js, png, err = _paths(manager, job_id)
    store = resume_store(manager, job_id)
    try:
        problem = spec.to_problem()
        client = manager.client
        chunk = max(1, math.ceil(req.n_particles / _n_workers(client)))
        with reg.lock:
            stop = reg.cancel.setdefault(job_id, threading.Event())
        cmap = CachedMap(dask_map(client, stop, reg.stopping), store)

        def progress(ev: dict) -> None:
            reg.progress[job_id] = jsonable(ev)

        report = diagnose(problem, candidates=req.candidates, n_particles=req.n_particles, seed=req.seed,
                          map=cancellable(cmap, stop), chunk_size=chunk, max_refits=req.max_refits,
                          refit_particles=req.refit_particles, continuation=req.continuation, progress=progress)
        d = jsonable(account(report.to_dict(), cmap))   # a resumed run counts its earlier attempts' time
        d["request"] = req.model_dump()
        plot_atomic(report, problem, png)
        write_atomic(js, json.dumps(d).encode())       # the JSON's presence means "done"
        shutil.rmtree(store, ignore_errors=True)
        _request_path(manager, job_id).unlink(missing_ok=True)
    except DiagnosisCancelled:
        log.info("diagnosis of job %s cancelled", job_id)
        shutil.rmtree(store, ignore_errors=True)
        write_atomic(_cancelled_path(manager, job_id), b"cancelled by DELETE /jobs/{id}/diagnosis")
        _request_path(manager, job_id).unlink(missing_ok=True)
    except BaseException as exc:  # noqa: BLE001 - recorded as the diagnosis' failure
        if reg.stopping.is_set():     # the service is going down: resumed at its next start
            log.warning("diagnosis of job %s interrupted by the shutdown (%s: %s); it resumes at the next start",
                        job_id, type(exc).__name__, exc)
            return
        log.exception("diagnosis of job %s failed", job_id)
        try:
            write_atomic(err, f"{type(exc).__name__}: {exc}"[:4000].encode())
        except OSError:
            pass
        _request_path(manager, job_id).unlink(missing_ok=True)
    finally:
        with reg.lock:
            reg.running.pop(job_id, None)
            reg.progress.pop(job_id, None)
            reg.cancel.pop(job_id, None)


def _launch(manager, reg: _Registry, job_id: str, spec: JobSpec, req: DiagnoseRequest, resumes: int = 0) -> None:
    """Keep the request on disk, then start the diagnosis thread (the caller holds ``reg.lock``)."""
    write_atomic(_request_path(manager, job_id),
                 json.dumps({"request": req.model_dump(), "resumes": int(resumes)}).encode())
    t = threading.Thread(target=_run, args=(manager, reg, job_id, spec, req), name=f"vfinfer-diagnose-{job_id[:8]}",
                         daemon=True)
    reg.running[job_id] = t
    t.start()


def resume_pending(manager, reg: _Registry) -> list[str]:
    """Start again every diagnosis whose request is on disk without a result (a shutdown or a crash
    interrupted it); returns their job ids. A request for a job that is gone, or no longer done, is
    dropped with its store; one interrupted ``MAX_AUTO_RESUMES`` times is recorded as failed."""
    started = []
    for f in sorted(_stores_dir(manager).glob("*.diagnosis.request.json")):
        jid = f.name.split(".", 1)[0]
        if len(jid) != 32 or any(c not in "0123456789abcdef" for c in jid):
            continue                                     # not a name this service writes
        js, _, err = _paths(manager, jid)
        try:
            saved = json.loads(f.read_text())
            req = DiagnoseRequest.model_validate(saved["request"])
            resumes = int(saved.get("resumes", 0))
        except (OSError, ValueError, KeyError, TypeError) as exc:
            log.warning("dropping the unreadable diagnosis request %s (%s)", f.name, exc)
            f.unlink(missing_ok=True)
            continue
        rec = manager.db.get(jid)
        if rec is None or rec["state"] != "done" or js.exists():
            f.unlink(missing_ok=True)
            if rec is None:
                shutil.rmtree(resume_store(manager, jid), ignore_errors=True)
            continue
        if resumes >= MAX_AUTO_RESUMES:
            write_atomic(err, (f"InterruptedError: the diagnosis was interrupted {resumes + 1} times by a stop of "
                               f"the service and is not started again automatically; POST /jobs/{jid}/diagnose "
                               "again to go on from its finished simulations").encode())
            f.unlink(missing_ok=True)
            continue
        with reg.lock:
            if jid in reg.running:
                continue
            err.unlink(missing_ok=True)
            _launch(manager, reg, jid, JobSpec.from_json(rec["spec"]), req, resumes + 1)
        started.append(jid)
    if started:
        log.info("resuming %d interrupted diagnosis(es)", len(started))
    return started


def on_startup(app, manager) -> list[str]:
    """The app's diagnosis registry, and the interrupted diagnoses started again (lifespan)."""
    with _REG_LOCK:
        reg = getattr(app.state, "diagnoses", None)
        if reg is None:
            reg = app.state.diagnoses = _Registry()
    return resume_pending(manager, reg)


def on_shutdown(app) -> None:
    """From now on a diagnosis that fails was interrupted: it resumes at the next start."""
    reg = getattr(app.state, "diagnoses", None)
    if reg is not None:
        reg.stopping.set()


# ------------------------------------------------------------------------------------ routes
@router.post("/jobs/{job_id}/diagnose", status_code=status.HTTP_202_ACCEPTED, response_model=DiagnoseStarted,
             summary="Start a diagnosis of a finished job: which physics is the model missing?")
def start_diagnosis(job_id: JobIdDep, user: UserDep, manager: ManagerDep, request: Request,
                    req: DiagnoseRequest | None = Body(default=None)) -> DiagnoseStarted:
    rec = done_job(manager, job_id, user)
    spec = JobSpec.from_json(rec["spec"])
    if spec.model != "fe":
        raise HTTPException(422, [{"loc": ["path", "job_id"], "type": "value_error",
                                   "msg": f"diagnosis needs a job of the finite-element model ('fe'), "
                                          f"this one is {spec.model!r}"}])
    req = req or DiagnoseRequest()
    reg = _registry(request)
    jid = rec["id"]
    with reg.lock:
        if jid in reg.running:
            raise HTTPException(status.HTTP_409_CONFLICT, "a diagnosis of this job is already running")
        js, png, err = _paths(manager, jid)
        for p in (js, png, err, _cancelled_path(manager, jid)):    # a new diagnosis replaces the previous result
            p.unlink(missing_ok=True)
        _launch(manager, reg, jid, spec, req)
    return DiagnoseStarted(id=jid, state="running", status_url=f"/jobs/{jid}/diagnosis")


@router.get("/jobs/{job_id}/diagnosis", response_model=DiagnosisStatus,
            summary="A diagnosis's state, current stage and, when done, its report")
def get_diagnosis(job_id: JobIdDep, user: UserDep, manager: ManagerDep, request: Request) -> DiagnosisStatus:
    rec = own_job(manager, job_id, user)
    jid = rec["id"]
    reg = _registry(request)
    with reg.lock:
        if jid in reg.running:
            return DiagnosisStatus(state="running", progress=reg.progress.get(jid))
    js, _, err = _paths(manager, jid)
    if js.exists():
        return DiagnosisStatus(state="done", report=json.loads(js.read_text()))
    if err.exists():
        return DiagnosisStatus(state="failed", error=err.read_text())
    if _cancelled_path(manager, jid).exists():
        return DiagnosisStatus(state="cancelled")
    return DiagnosisStatus(state="none")


@router.delete("/jobs/{job_id}/diagnosis", status_code=status.HTTP_202_ACCEPTED, summary="Cancel a running diagnosis")
def cancel_diagnosis(job_id: JobIdDep, user: UserDep, manager: ManagerDep, request: Request) -> dict:
    """Cancel a running diagnosis: it stops within a quarter of a second of waiting on the cluster
    (its batch's unstarted simulations are cancelled; :func:`dask_map`), its stored simulations
    are deleted and its state becomes "cancelled"."""
    rec = own_job(manager, job_id, user)
    jid = rec["id"]
    reg = _registry(request)
    with reg.lock:
        if jid not in reg.running:
            raise HTTPException(status.HTTP_409_CONFLICT, "no diagnosis of this job is running")
        reg.cancel.setdefault(jid, threading.Event()).set()
    return {"id": jid, "state": "cancelling", "status_url": f"/jobs/{jid}/diagnosis"}


@router.get("/jobs/{job_id}/diagnosis/figure", responses={200: {"content": {"image/png": {}}}},
            summary="A finished diagnosis's figure (PNG): base fit, located mismatch, named extension")
def get_diagnosis_figure(job_id: JobIdDep, user: UserDep, manager: ManagerDep, request: Request) -> Response:
    rec = own_job(manager, job_id, user)
    jid = rec["id"]
    reg = _registry(request)
    with reg.lock:
        running = jid in reg.running
    js, png, _ = _paths(manager, jid)
    if running or not (js.exists() and png.exists()):
        raise HTTPException(status.HTTP_404_NOT_FOUND, "diagnosis figure not available")
    return Response(png.read_bytes(), media_type="image/png")


def diagnosis_report_scope(job_id: str) -> str:
    """The signed-link scope of a job's diagnosis page: another page than the job's report, so a link to one
    never opens the other."""
    return f"diagnosis-report/{job_id}"


@router.get("/jobs/{job_id}/diagnosis/report", response_class=HTMLResponse,
            summary="A finished diagnosis as one self-contained HTML page (figure embedded): verdict, located "
                    "mismatch, ranked catalogue entries, cost; opens with the bearer token or with a signed link "
                    "from POST /jobs/{id}/diagnosis/report-link",
            responses={401: {"description": "neither a bearer token nor a signed link"},
                       403: {"description": "a signed link that is expired, altered or made for another page"},
                       404: {"description": "no such job of yours, or no finished diagnosis of it"}})
def get_diagnosis_report(job_id: JobIdDep, manager: ManagerDep, signer: SignerDep, user: OptionalUserDep,
                         request: Request, exp: Exp = None, sig: Sig = None) -> HTMLResponse:
    from ..report import PAGE_HEADERS, data_uri
    from ..report_diagnose import render_diagnosis_report
    user = page_reader(manager, job_id, user, signer, diagnosis_report_scope(job_id), exp, sig,
                       "POST /jobs/{id}/diagnosis/report-link")
    jid = _done_diagnosis(manager, job_id, user, request)
    js, png, _ = _paths(manager, jid)
    d = json.loads(js.read_text())
    fig = data_uri(png.read_bytes()) if png.exists() else None
    return HTMLResponse(render_diagnosis_report(d, fig, f"vfinfer diagnosis of job {jid}", source={"job": jid}),
                        headers=PAGE_HEADERS)


@router.post("/jobs/{job_id}/diagnosis/report-link", response_model=LinkOut,
             summary="A short-lived signed link to a finished diagnosis's HTML page that a browser opens without "
                     "the bearer token")
def diagnosis_report_link(job_id: JobIdDep, user: UserDep, manager: ManagerDep, signer: SignerDep,
                          request: Request) -> LinkOut:
    jid = _done_diagnosis(manager, job_id, user, request)
    return link_out(request, signer.sign(diagnosis_report_scope(jid), f"/jobs/{jid}/diagnosis/report"))


def _done_diagnosis(manager, job_id: str, user: str, request: Request) -> str:
    """The id of ``user``'s job whose diagnosis is finished; 404 otherwise (as the figure)."""
    jid = own_job(manager, job_id, user)["id"]
    reg = _registry(request)
    with reg.lock:
        running = jid in reg.running
    if running or not _paths(manager, jid)[0].exists():
        raise HTTPException(status.HTTP_404_NOT_FOUND, "no finished diagnosis of this job")
    return jid
