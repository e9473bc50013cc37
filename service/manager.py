"""Job manager: a FIFO queue drained by a few runner threads that drive jobs on the Dask cluster.

Two kinds of job go through it: an inference (``worker.run.run_job``) and a diagnosis of a finished
inference (``service.diagnosis.run_diagnosis``). The runner threads only orchestrate (submit chunks,
wait, read the store); every simulation and reduction happens on the Dask workers.  State lives in
SQLite; progress is kept in memory (fast status calls) and written to SQLite at most once a second.
At start-up every job that was queued or running is re-queued: an inference skips the chunks its
store already marks done, a diagnosis reads its finished simulations back from its store.  A cancel
(``cancel``) and a shutdown (``stop``) stop a job the same way; a cancelled job is marked so, a job
stopped by a shutdown stays ``running`` and goes on at the next start.
"""

from __future__ import annotations

import logging
import queue
import shutil
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from vfcore.strict_json import jsonable
from worker.jobspec import JobSpec
from worker.run import JobCancelled, JobControl, Progress, cluster_threads, register_warm_up, run_job
from worker.store import create_diagnosis_store

from . import diagnosis as dg
from .api_models import DiagnoseRequest, DiagnosisSpec
from .db import ACTIVE, JobDB, new_job_id
from .diagnosis_import import import_legacy_diagnoses
from .settings import Settings

log = logging.getLogger("vfinfer.manager")

_STOP = object()
#: Stats written at submission (service.routers.jobs.reach_gate) that a finished run keeps.
SUBMIT_NOTES = ("reach", "warnings")
#: Automatic restarts of one interrupted diagnosis before it is recorded as failed: a diagnosis that brings
#: the service down would otherwise do so at every start.
MAX_AUTO_RESUMES = 3


class DiagnosisRunning(Exception):
    """A diagnosis of this job is already queued or running (one at a time per job)."""


@dataclass
class Live:
    progress: Progress
    control: JobControl
    started: float
    last_flush: float = 0.0
    #: a diagnosis: its latest progress event (vfcore.diagnose.progress), as the API shows it
    event: dict | None = None


class JobManager:
    def __init__(self, settings: Settings, db: JobDB, client):
        self.settings = settings
        self.db = db
        self.client = client
        self._q: queue.Queue = queue.Queue()
        self._live: dict[str, Live] = {}
        self._lock = threading.Lock()
        self._threads: list[threading.Thread] = []
        self._stopping = threading.Event()
        self._submit_lock = threading.Lock()
        settings.stores_dir.mkdir(parents=True, exist_ok=True)

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> int:
        """Start the runner threads and re-queue unfinished jobs; returns how many were re-queued."""
        if self.client is not None:
            register_warm_up(self.client)
        import_legacy_diagnoses(self)
        pending = self.db.list(states=ACTIVE, kind=None)
        for rec in pending:
            self._q.put(rec["id"])
        for i in range(self.settings.max_running_jobs):
            t = threading.Thread(target=self._loop, name=f"vfinfer-runner-{i}", daemon=True)
            t.start()
            self._threads.append(t)
        if pending:
            log.info("resuming %d unfinished job(s)", len(pending))
        return len(pending)

    def stop(self, timeout: float = 10.0) -> None:
        """Stop driving jobs; running jobs stay 'running' in the table and resume at the next start."""
        self._stopping.set()
        with self._lock:
            lives = list(self._live.values())
        for lv in lives:
            lv.control.cancel()
        for _ in self._threads:
            self._q.put(_STOP)
        for t in self._threads:
            t.join(timeout)

    # ------------------------------------------------------------------ API used by the routes
    def store_path(self, job_id: str) -> Path:
        # job_id was produced by new_job_id() and read back from the table, never from a request
        return self.settings.stores_dir / f"{job_id}.zarr"

    def submit(self, owner: str, spec: JobSpec, notes: dict | None = None) -> str:
        """Queue a job; ``notes`` (the reach check and its warnings) start the job's stats and outlive its runs."""
        job_id = new_job_id()
        self.db.insert(job_id, owner, spec.to_json(), spec.n_simulations)
        if notes:
            self.db.update(job_id, stats=notes)
        self._q.put(job_id)
        return job_id

    def submit_diagnosis(self, owner: str, job_id: str, request: DiagnoseRequest) -> str:
        """Queue a diagnosis of the finished job ``job_id``; it replaces the job's previous diagnosis and goes on
        from the simulations a failed one left. Raises :class:`DiagnosisRunning` while one is queued or running."""
        spec = DiagnosisSpec(job=job_id, request=request, parts=cluster_threads(self.client))
        diag_id = new_job_id()
        with self._submit_lock:
            earlier = self.db.children(job_id)
            if any(r["state"] in ACTIVE for r in earlier):
                raise DiagnosisRunning(job_id)
            store = self.store_path(diag_id)
            create_diagnosis_store(store, diag_id, spec.to_json())
            for r in earlier:
                dg.adopt_resume(self.store_path(r["id"]), store)
                self.db.delete(r["id"])
                shutil.rmtree(self.store_path(r["id"]), ignore_errors=True)
            self.db.insert(
                diag_id, owner, spec.to_json(), 0, kind="diagnosis", parent=job_id, sampler="smc", model="fe"
            )
        self._q.put(diag_id)
        return diag_id

    def cancel(self, job_id: str) -> bool:
        changed = self.db.update(job_id, only_if_state=ACTIVE, state="cancelled", finished=time.time())
        with self._lock:
            lv = self._live.get(job_id)
        if lv is not None:
            lv.control.cancel()
        elif changed:
            self._discard(job_id)
        return changed

    def _discard(self, job_id: str) -> None:
        """What a cancelled job leaves: a diagnosis's stored simulations go (an inference keeps its store)."""
        rec = self.db.get(job_id)
        if rec is not None and rec["kind"] == "diagnosis":
            dg.discard_resume(self.store_path(job_id))

    def live(self, job_id: str) -> Live | None:
        with self._lock:
            return self._live.get(job_id)

    def queue_length(self) -> int:
        return self._q.qsize()

    # ------------------------------------------------------------------ runner
    def _loop(self) -> None:
        while not self._stopping.is_set():
            item = self._q.get()
            if item is _STOP:
                return
            try:
                self._run(item)
            except Exception:  # noqa: BLE001 - a runner thread must survive any job
                log.exception("runner crashed on job %s", item)

    def _run(self, job_id: str) -> None:
        rec = self.db.get(job_id)
        if rec is None or rec["state"] not in ACTIVE or self._stopping.is_set():
            return
        if rec["kind"] == "diagnosis" and rec["state"] == "running" and rec["attempts"] > MAX_AUTO_RESUMES:
            self.db.update(
                job_id,
                only_if_state=ACTIVE,
                state="failed",
                finished=time.time(),
                error=(
                    f"InterruptedError: the diagnosis was interrupted {rec['attempts']} times by a stop of the service "
                    f"and is not started again automatically; POST /jobs/{rec['parent']}/diagnose again to go on from "
                    "its finished simulations"
                ),
            )
            return
        now = time.time()
        if not self.db.update(
            job_id, only_if_state=ACTIVE, state="running", started=rec["started"] or now, attempts=rec["attempts"] + 1
        ):
            return
        lv = Live(progress=Progress(n_total=rec["n_total"]), control=JobControl(), started=now)
        with self._lock:
            self._live[job_id] = lv
        if self.db.get(job_id)["state"] == "cancelled":  # cancelled between the two updates
            lv.control.cancel()
        work = self._diagnose if rec["kind"] == "diagnosis" else self._infer
        try:
            stats, done = work(rec, lv)
        except JobCancelled:
            if not self._stopping.is_set():
                self.db.update(job_id, only_if_state=ACTIVE, state="cancelled", finished=time.time())
                self._discard(job_id)
            return
        except Exception as exc:  # noqa: BLE001 - recorded as the job's error
            if self._stopping.is_set():  # e.g. the cluster went first: an interruption, resumed
                return
            if lv.control.cancelled.is_set():
                self._discard(job_id)
                return
            log.exception("job %s failed", job_id)
            self.db.update(
                job_id,
                only_if_state=("running",),
                state="failed",
                finished=time.time(),
                error=f"{type(exc).__name__}: {exc}"[:2000],
            )
            return
        finally:
            with self._lock:
                self._live.pop(job_id, None)
        prev = rec["stats"] or {}
        stats["runs"] = prev.get("runs", []) + [
            {k: stats[k] for k in ("chunks_computed", "chunks_skipped", "total_s") if k in stats}
        ]
        stats["queued_s"] = (rec["started"] or now) - rec["created"]
        for k in SUBMIT_NOTES:
            if k in prev:
                stats[k] = prev[k]
        self.db.update(job_id, only_if_state=("running",), state="done", finished=time.time(), stats=stats, **done)

    def _flusher(self, job_id: str, lv: Live):
        """Keep ``lv.progress`` current, and the table at most once a second."""

        def report(p: Progress) -> None:
            lv.progress = p
            t = time.monotonic()
            if t - lv.last_flush > 1.0:
                lv.last_flush = t
                self.db.update(
                    job_id,
                    only_if_state=("running",),
                    n_done=p.n_done,
                    n_total=max(p.n_total, p.n_done),
                    ess=_finite(p.ess),
                )

        return report

    def _infer(self, rec: dict, lv: Live) -> tuple[dict, dict]:
        job_id = rec["id"]
        spec = JobSpec.from_json(rec["spec"])
        stats = run_job(
            self.client, job_id, self.store_path(job_id), spec, report=self._flusher(job_id, lv), control=lv.control
        )
        n = stats["n_simulations"]
        return stats, {"n_done": n, "n_total": n, "ess": _finite(stats["ess"])}

    def _diagnose(self, rec: dict, lv: Live) -> tuple[dict, dict]:
        job_id = rec["id"]
        spec = DiagnosisSpec.model_validate_json(rec["spec"])
        job = self.db.get(spec.job)
        if job is None or job["state"] != "done":
            raise RuntimeError(
                f"the job it diagnoses ({spec.job}) is {'gone' if job is None else job['state'] + ', not done'}"
            )
        problem = JobSpec.from_json(job["spec"]).to_problem()
        flush = self._flusher(job_id, lv)

        def progress(ev: dict) -> None:
            lv.event = jsonable(ev)
            flush(Progress(n_done=int(ev.get("simulations") or 0), phase=str(ev.get("stage"))))

        base = dg.job_posterior(self.store_path(spec.job)) if spec.request.reuse_posterior else None
        stats = dg.run_diagnosis(
            self.client,
            job_id,
            self.store_path(job_id),
            spec,
            problem,
            stop=lv.control.cancelled,
            progress=progress,
            base=base,
        )
        n = stats["n_simulations"]
        return stats, {"n_done": n, "n_total": n}


def _finite(x) -> float | None:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if x == x and abs(x) != float("inf") else None
