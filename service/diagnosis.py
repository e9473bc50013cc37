"""A diagnosis job: :mod:`vfcore.diagnose` run on a finished inference job's problem, its simulations on the
service's Dask cluster, its report and figure written into its own store.

The job manager runs it like an inference (:func:`run_diagnosis`); ``vfinfer diagnose`` runs the same call
(:func:`run_diagnose`) on this machine. While it runs, every finished part of a batch is kept in the store's
``resume/`` folder (:class:`vfcore.inference.memo.CachedMap`), so a run started again after a restart reads
them back. The diagnosis is deterministic given its settings and seed, so the resumed run's report equals the
uninterrupted one's: the store keeps the report without its clock readings (wall times, the time by stage, what
the resume store contributed), which go to the job's stats and are merged back when the report is served.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import threading
from pathlib import Path

from vfcore.strict_json import jsonable
from worker import store as st
from worker.run import JobCancelled, cluster_threads

#: how often (s) a map waiting on a running simulation looks whether it was cancelled
POLL_S = 0.25
#: matplotlib's pyplot is not thread-safe: one figure at a time in this process.
_PLOT_LOCK = threading.Lock()
#: Report entries that are clock readings or say how this run went, not what it found.
CLOCK_KEYS = ("wall_s",)
RUN_KEYS = ("cost", "resume_store")


class DiagnosisCancelled(JobCancelled):
    """Raised inside a running diagnosis once it is cancelled or the service stops (within a poll,
    :func:`dask_map`); the manager tells the two apart."""


# ------------------------------------------------------------------------------------ the one call of vfcore
def run_diagnose(problem, request, *, map=map, chunk_size: int | None = None, progress=None, base=None):
    """``vfcore.diagnose`` on ``problem`` with a :class:`~service.api_models.DiagnoseRequest`'s settings
    (:meth:`~service.api_models.DiagnoseRequest.settings`; every other setting the library's default): the only
    place the service and the CLI call it (``chunk_size`` None: the library's). ``base``: a fitted posterior of
    the recording to start from (the diagnosis' ``base``)."""
    from vfcore.diagnose import pipeline

    kw = request.settings() | ({} if chunk_size is None else {"chunk_size": chunk_size})
    return pipeline.diagnose(problem, map=map, base=base, progress=progress, **kw)


def plot(report, problem, path: Path) -> None:
    """The diagnosis figure (``vfcore.diagnose``'s plot) as a PNG file."""
    from vfcore.diagnose import pipeline

    with _PLOT_LOCK:
        pipeline.plot_diagnosis(report, problem, path)


def figure_png(report, problem, folder: Path) -> bytes:
    tmp = Path(folder) / f".figure.{secrets.token_hex(6)}.png"
    try:
        plot(report, problem, tmp)
        return tmp.read_bytes()
    finally:
        tmp.unlink(missing_ok=True)


# ------------------------------------------------------------------------------------ the cluster
def dask_map(client, stop: threading.Event | None = None):
    """A builtin-map-like callable running every call on the Dask cluster.

    Results come back in order, each as soon as it and those before it are done, so the
    diagnosis' store (:class:`vfcore.inference.memo.CachedMap`) keeps every finished part of a
    batch that is later interrupted. While it waits it looks every ``POLL_S`` seconds at ``stop``
    (set by a cancel or a shutdown: :class:`DiagnosisCancelled`) and then cancels the batch's
    unfinished futures, so a cancel takes effect within a poll, not after the batch in flight."""
    if client is None:
        return map

    def _check():
        if stop is not None and stop.is_set():
            raise DiagnosisCancelled("cancelled")

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
        finally:  # stopped early, failed or cancelled: drop what is left
            left = [f for f in futures if not f.done()]
            if left:
                client.cancel(left)

    return _map


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


# ------------------------------------------------------------------------------------ the report in the store
def split_clock(report: dict) -> tuple[dict, list]:
    """``report`` without its clock readings and run accounts (:data:`CLOCK_KEYS` at any depth, :data:`RUN_KEYS`
    at the top), and those as ``[[path, value], ...]`` for :func:`merge_clock`."""
    clock: list = []

    def walk(x, path):
        if isinstance(x, dict):
            out = {}
            for k, v in x.items():
                if k in CLOCK_KEYS or (not path and k in RUN_KEYS):
                    clock.append([path + [k], v])
                else:
                    out[k] = walk(v, path + [k])
            return out
        if isinstance(x, list):
            return [walk(v, path + [i]) for i, v in enumerate(x)]
        return x

    return walk(report, []), clock


def merge_clock(report: dict, clock: list) -> dict:
    """The report :func:`split_clock` split, whole again (a path that no longer leads anywhere is skipped)."""
    out = json.loads(json.dumps(report))
    for path, value in clock or []:
        node = out
        try:
            for k in path[:-1]:
                node = node[k]
            node[path[-1]] = value
        except (KeyError, IndexError, TypeError):
            continue
    return out


def report_bytes(store_path: Path) -> bytes | None:
    """The stored report (JSON, no clock readings); None until the diagnosis is done."""
    return st.read_blob(store_path, "diagnosis_json")


def read_report(store_path: Path, stats: dict, request: dict | None) -> dict | None:
    """The report as the API serves it: the stored one, its clock readings and the request that made it."""
    raw = report_bytes(store_path)
    if raw is None:
        return None
    d = merge_clock(json.loads(raw), (stats or {}).get("clock", []))
    if request is not None:
        d["request"] = request
    return d


def write_report(store_path: Path, job_id: str, spec_json: str, report: dict, png: bytes | None) -> list:
    """Store a finished diagnosis (figure first, then the report, whose presence means done); returns the
    clock readings for the job's stats."""
    timeless, clock = split_clock(jsonable(report))
    root = st.create_diagnosis_store(store_path, job_id, spec_json)
    if png is not None:
        st.write_blob(root, "diagnosis_png", png)
    st.write_blob(root, "diagnosis_json", json.dumps(timeless).encode())
    return clock


def resume_dir(store_path: Path) -> Path:
    return Path(store_path) / st.RESUME_DIR


def discard_resume(store_path: Path) -> None:
    shutil.rmtree(resume_dir(store_path), ignore_errors=True)


def adopt_resume(old_store: Path, new_store: Path) -> bool:
    """Move the finished simulations an earlier diagnosis of the same job left (one that failed) into a new
    diagnosis's store, which reads back whatever parts the two share."""
    src, dst = resume_dir(old_store), resume_dir(new_store)
    if not src.is_dir() or dst.exists():
        return False
    os.replace(src, dst)
    return True


def job_posterior(store_path: Path):
    """A finished inference job's posterior from its store (its ``posterior.nc``), or None when the store
    keeps none or one without predicted GAWs (a diagnosis then fits its base itself)."""
    from vfcore.inference.posterior import Posterior

    data = st.read_blob(Path(store_path), "posterior_nc")
    if not data:
        return None
    tmp = Path(store_path).parent / f".{Path(store_path).name}.{secrets.token_hex(6)}.nc"
    try:
        tmp.write_bytes(data)
        post = Posterior.from_netcdf(tmp)
    finally:
        tmp.unlink(missing_ok=True)
    return post if post.predictive is not None else None


def expected(job_spec_json: str, store_path: Path, request):
    """What a diagnosis of the finished job (its spec ``job_spec_json``, its store ``store_path``) with
    ``request`` is expected to cost, in simulations (:func:`vfcore.diagnose.expected.expected_for`): the
    job's own posterior is its base fit when ``request.reuse_posterior`` and the store keeps one. No time per
    simulation: the service does not time the cluster's workers."""
    from vfcore.diagnose.expected import expected_for
    from worker.jobspec import JobSpec

    problem = JobSpec.from_json(job_spec_json).to_problem()
    base = job_posterior(store_path) if request.reuse_posterior else None
    return expected_for(problem, request.options(), None, 1, base)


# ------------------------------------------------------------------------------------ the job
def run_diagnosis(
    client, job_id: str, store_path: Path, spec, problem, *, stop: threading.Event, progress=None, base=None
) -> dict:
    """Run (or resume) the diagnosis job ``spec`` (a :class:`~service.api_models.DiagnosisSpec`) of ``problem`` to
    its stored report; returns its stats (the report's clock readings, the simulations). Raises
    :class:`DiagnosisCancelled` once ``stop`` is set. ``base``: the diagnosed job's posterior
    (:func:`job_posterior`) to start from, or None."""
    from vfcore.inference.importance import BalancedMap
    from vfcore.inference.memo import CachedMap, account

    st.create_diagnosis_store(store_path, job_id, spec.to_json())
    cmap = CachedMap(dask_map(client, stop), resume_dir(store_path))
    if spec.chunk_size and not spec.parts:  # a spec stored with fixed chunks keeps them
        inner, chunk = cmap, spec.chunk_size
    else:  # every batch in equal parts, one per worker thread
        inner, chunk = BalancedMap(cmap, spec.parts or cluster_threads(client)), None
    report = run_diagnose(
        problem, spec.request, map=cancellable(inner, stop), chunk_size=chunk, progress=progress, base=base
    )
    d = account(report.to_dict(), cmap)  # a resumed run counts its earlier attempts' time
    png = figure_png(report, problem, store_path)
    clock = write_report(store_path, job_id, spec.to_json(), d, png)
    discard_resume(store_path)
    return {"clock": clock, "n_simulations": int(d.get("n_simulations") or 0), "total_s": float(d.get("wall_s") or 0.0)}
