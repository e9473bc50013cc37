"""Job manager: a FIFO queue drained by a few runner threads that drive jobs on the Dask cluster.

The runner threads only orchestrate (submit chunks, wait, read the store); all simulation and
reduction happens on the Dask workers.  State lives in SQLite; progress is kept in memory (fast
status calls) and written to SQLite at most once a second.  At start-up every job that was
queued or running is re-queued: ``worker.run.run_job`` then skips the chunks its store already
marks done.
"""
from __future__ import annotations

import logging
import queue
import secrets
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from worker.jobspec import JobSpec
from worker.run import JobCancelled, JobControl, Progress, register_warm_up, run_job

from .db import ACTIVE, JobDB
from .settings import Settings

log = logging.getLogger("vfinfer.manager")

_STOP = object()
#: Stats written at submission (service.routers.jobs.reach_gate) that a finished run keeps.
SUBMIT_NOTES = ("reach", "warnings")


def new_job_id() -> str:
    """128 random bits as 32 hex digits: unguessable, the only thing a store path is built from,
    and never starting with "-" (a URL-safe token does 1 time in 64, and the CLI then reads the id
    as an option: ``vfinfer status -n...`` failed with "No such option: -n")."""
    return secrets.token_hex(16)


@dataclass
class Live:
    progress: Progress
    control: JobControl
    started: float
    last_flush: float = 0.0


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
        settings.stores_dir.mkdir(parents=True, exist_ok=True)

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> int:
        """Start the runner threads and re-queue unfinished jobs; returns how many were re-queued."""
        if self.client is not None:
            register_warm_up(self.client)
        pending = self.db.list(states=ACTIVE)
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

    def cancel(self, job_id: str) -> bool:
        changed = self.db.update(job_id, only_if_state=ACTIVE, state="cancelled", finished=time.time())
        with self._lock:
            lv = self._live.get(job_id)
        if lv is not None:
            lv.control.cancel()
        return changed

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
        spec = JobSpec.from_json(rec["spec"])
        now = time.time()
        if not self.db.update(job_id, only_if_state=ACTIVE, state="running", started=rec["started"] or now,
                              attempts=rec["attempts"] + 1):
            return
        lv = Live(progress=Progress(n_total=rec["n_total"]), control=JobControl(), started=now)
        with self._lock:
            self._live[job_id] = lv
        if self.db.get(job_id)["state"] == "cancelled":   # cancelled between the two updates
            lv.control.cancel()

        def report(p: Progress) -> None:
            lv.progress = p
            t = time.monotonic()
            if t - lv.last_flush > 1.0:
                lv.last_flush = t
                self.db.update(job_id, only_if_state=("running",), n_done=p.n_done,
                               n_total=max(p.n_total, p.n_done), ess=_finite(p.ess))

        try:
            stats = run_job(self.client, job_id, self.store_path(job_id), spec, report=report, control=lv.control)
        except JobCancelled:
            if not self._stopping.is_set():
                self.db.update(job_id, only_if_state=ACTIVE, state="cancelled", finished=time.time())
            return
        except Exception as exc:  # noqa: BLE001 - recorded as the job's error
            if self._stopping.is_set() or lv.control.cancelled.is_set():
                return
            log.exception("job %s failed", job_id)
            self.db.update(job_id, only_if_state=("running",), state="failed", finished=time.time(),
                           error=f"{type(exc).__name__}: {exc}"[:2000])
            return
        finally:
            with self._lock:
                self._live.pop(job_id, None)
        prev = rec["stats"] or {}
        stats["runs"] = prev.get("runs", []) + [{k: stats[k] for k in ("chunks_computed", "chunks_skipped",
                                                                      "total_s")}]
        stats["queued_s"] = (rec["started"] or now) - rec["created"]
        for k in SUBMIT_NOTES:
            if k in prev:
                stats[k] = prev[k]
        self.db.update(job_id, only_if_state=("running",), state="done", finished=time.time(),
                       n_done=stats["n_simulations"], n_total=stats["n_simulations"], ess=_finite(stats["ess"]),
                       stats=stats)


def _finite(x) -> float | None:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if x == x and abs(x) != float("inf") else None
