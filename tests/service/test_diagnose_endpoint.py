"""POST /jobs/{id}/diagnose, GET /jobs/{id}/diagnosis(/figure): ownership, states, validation, and one
real (tiny) diagnosis of a finished finite-element job on the service's Dask cluster. A diagnosis is a
job of the job table run by the job manager: resumed after a stop, cancelled by DELETE."""

from __future__ import annotations

import time

import numpy as np
import pytest
from svc_helpers import auth, done_fe_job, dying_diagnosis, toy_spec, wait_done

FPS = 4000.0


def _wait_diagnosis(http, job_id, user, timeout=300.0, progress: list | None = None) -> dict:
    t0 = time.time()
    while True:
        r = http.get(f"/jobs/{job_id}/diagnosis", headers=auth(user))
        assert r.status_code == 200, r.text
        d = r.json()
        if d["state"] in ("done", "failed"):
            return d
        assert d["state"] in ("queued", "running"), d
        if progress is not None and d["progress"] is not None:
            progress.append(d["progress"])
        if time.time() - t0 > timeout:
            raise TimeoutError(f"diagnosis of {job_id} still running")
        time.sleep(0.25)


def test_diagnose_rules(service):
    http = service.http
    # a finished toy job: ownership and the fe-only rule
    r = http.post("/jobs", json=toy_spec(n=20), headers=auth("alice"))
    assert r.status_code == 202, r.text
    toy = r.json()["id"]
    assert wait_done(http, toy, "alice")["state"] == "done"
    for method, path in (
        ("post", f"/jobs/{toy}/diagnose"),
        ("get", f"/jobs/{toy}/diagnosis"),
        ("get", f"/jobs/{toy}/diagnosis/figure"),
    ):
        assert getattr(http, method)(path, headers=auth("bob")).status_code == 404, path
    assert http.get(f"/jobs/{'x' * 32}/diagnosis", headers=auth("alice")).status_code == 404
    r = http.post(f"/jobs/{toy}/diagnose", headers=auth("alice"))
    assert r.status_code == 422 and "fe" in r.text, r.text
    # nothing ever started on it
    assert http.get(f"/jobs/{toy}/diagnosis", headers=auth("alice")).json() == {
        "state": "none",
        "error": None,
        "report": None,
        "progress": None,
        "diagnosis_id": None,
    }
    assert http.get(f"/jobs/{toy}/diagnosis/figure", headers=auth("alice")).status_code == 404
    # body validation: unknown / unimplemented candidates are named, ranges enforced, extras refused
    r = http.post(f"/jobs/{toy}/diagnose", json={"candidates": ["leak", "warp_drive"]}, headers=auth("alice"))
    assert r.status_code == 422 and "warp_drive" in r.text and "leak'" not in r.text.split("known")[0], r.text
    for body in (
        {"n_particles": 5},
        {"n_particles": 401},
        {"max_refits": 7},
        {"refit_particles": 3},
        {"candidates": []},
        {"colour": "red"},
        {"refit_start": "posterior"},
    ):
        assert http.post(f"/jobs/{toy}/diagnose", json=body, headers=auth("alice")).status_code == 422, body
    # a job that is not done: 409
    r = http.post("/jobs", json=toy_spec(n=400, delay=0.05), headers=auth("alice"))
    slow = r.json()["id"]
    r = http.post(f"/jobs/{slow}/diagnose", headers=auth("alice"))
    assert r.status_code == 409 and "not done" in r.text, r.text
    http.delete(f"/jobs/{slow}", headers=auth("alice"))


@pytest.fixture(scope="module")
def leaky_spec():
    """A tiny FE job on a Table 3 simulation with a 1.5 mm^2 leak and N(0, 0.3^2) noise."""
    pytest.importorskip("vfcore.forward", reason="FE forward model not available")
    from svc_helpers import leaky_fe_spec

    return leaky_fe_spec(FPS)


@pytest.mark.slow
def test_diagnose_finished_fe_job(service, leaky_spec):
    http = service.http
    r = http.post("/jobs", json=leaky_spec, headers=auth("alice"))
    assert r.status_code == 202, r.text
    job = r.json()["id"]
    assert wait_done(http, job, "alice", timeout=300)["state"] == "done"

    # the search and the material-first stage are tested in tests/vfcore (a one-parameter problem here)
    body = {
        "candidates": ["leak"],
        "n_particles": 12,
        "max_refits": 1,
        "seed": 0,
        "continuation": False,
        "free_material": False,
    }
    t0 = time.perf_counter()
    r = http.post(f"/jobs/{job}/diagnose", json=body, headers=auth("alice"))
    assert r.status_code == 202, r.text
    assert r.json()["status_url"] == f"/jobs/{job}/diagnosis"
    assert r.json()["expected"]["base_fits"] == 0 and r.json()["expected"]["floor_simulations"] == [0, 0]
    diag = r.json()["diagnosis_id"]
    # one at a time per job; the figure is not served while it runs
    assert http.post(f"/jobs/{job}/diagnose", json=body, headers=auth("alice")).status_code == 409
    assert http.get(f"/jobs/{job}/diagnosis/figure", headers=auth("alice")).status_code == 404
    assert http.get(f"/jobs/{job}/diagnosis", headers=auth("bob")).status_code == 404

    seen = []
    d = _wait_diagnosis(http, job, "alice", progress=seen)
    wall = time.perf_counter() - t0
    assert d["state"] == "done", d
    # while it ran, the status told where it was: known stages, simulations only growing
    from vfcore.diagnose.progress import STAGES

    assert seen and all(p["stage"] in STAGES for p in seen), seen
    assert [p["simulations"] for p in seen] == sorted(p["simulations"] for p in seen)
    assert seen[-1]["simulations"] > 0 and d["progress"] is None
    rep = d["report"]
    assert isinstance(rep["verdict"], str) and rep["verdict"]
    assert rep["winner"] == "leak", rep["verdict"]  # the hidden 1.5 mm^2 leak is found
    assert rep["n_simulations"] > 0 and rep["base"]["residual_rms"] > 0
    assert set(rep["screening"]) >= {"leak"} and rep["request"]["n_particles"] == 12
    assert rep["wall_s"] <= wall + 1.0
    assert rep["resume_store"]["earlier_attempts"] == 0 and rep["resume_store"]["parts_simulated"] > 0
    fig = http.get(f"/jobs/{job}/diagnosis/figure", headers=auth("alice"))
    assert fig.status_code == 200 and fig.headers["content-type"] == "image/png"
    assert fig.content[:8] == b"\x89PNG\r\n\x1a\n"
    assert http.get(f"/jobs/{job}/diagnosis/figure", headers=auth("bob")).status_code == 404
    # the diagnosis is a job of its own, its report and figure in its store, no temporary file left
    st = http.get(f"/jobs/{diag}", headers=auth("alice")).json()
    assert st["kind"] == "diagnosis" and st["parent"] == job and st["state"] == "done"
    assert st["progress"]["simulations_done"] == rep["n_simulations"]
    store = service.settings.stores_dir / f"{diag}.zarr"
    assert not [p.name for p in store.rglob(".*") if p.name.startswith((".figure", ".tmp"))]
    assert not (store / "resume").exists()  # the resume store goes once done


def test_a_failed_diagnosis_leaves_its_simulations_to_the_next_request(service, monkeypatch):
    """A diagnosis that evaluates a batch of 3 parts (6 rows) and then dies: the failure is recorded, the
    parts the store was given (the batch cut into one equal part per worker thread) stay in it, and the same
    request posted again reads every one back and simulates nothing."""
    import vfcore.diagnose.pipeline as P
    from service.diagnosis import resume_dir
    from vfcore.inference.importance import BalancedMap

    maps = []
    monkeypatch.setattr(P, "diagnose", dying_diagnosis(maps, "worker lost"))
    jid = done_fe_job(service.settings)
    http, stores = service.http, service.settings.stores_dir
    first = http.post(f"/jobs/{jid}/diagnose", json={"continuation": False}, headers=auth("alice")).json()
    d = _wait_diagnosis(http, jid, "alice", timeout=60)
    assert d["state"] == "failed" and "worker lost" in d["error"], d
    balanced = maps[0].inner  # inside the cancellable map
    assert isinstance(balanced, BalancedMap)
    stored = len(list(resume_dir(stores / f"{first['diagnosis_id']}.zarr").rglob("*.pkl")))
    assert stored == min(balanced.workers, 6) >= 1
    second = http.post(f"/jobs/{jid}/diagnose", json={"continuation": False}, headers=auth("alice")).json()
    assert _wait_diagnosis(http, jid, "alice", timeout=60)["state"] == "failed"
    store = maps[1].inner.inner  # the store, inside the balanced, cancellable map
    assert (store.hits, store.misses) == (stored, 0)
    assert store.earlier_attempts == 1  # the dead attempt's time is on record
    # the new diagnosis replaced the old one, which is gone with its store
    assert http.get(f"/jobs/{first['diagnosis_id']}", headers=auth("alice")).status_code == 404
    assert not (stores / f"{first['diagnosis_id']}.zarr").exists() and second["diagnosis_id"] != first["diagnosis_id"]


def test_a_diagnosis_announces_its_expected_simulations_when_queued(service, monkeypatch):
    """POST /jobs/{id}/diagnose answers the simulations of both outcomes before anything runs: the measured
    ranges at the defaults with one base fit, twice the base share when the parameters held at Table 3 are
    freed after a pinned fit, and the settings that scale the figures named."""
    import vfcore.diagnose.pipeline as P
    from vfcore.diagnose.expected import CATALOGUE_SIMULATIONS, FLOOR_SIMULATIONS
    from vfcore.diagnose.material import pinned
    from worker.jobspec import JobSpec

    monkeypatch.setattr(P, "diagnose", dying_diagnosis([], "stopped after the announcement"))
    jid = done_fe_job(service.settings)  # no posterior stored: the diagnosis fits its base itself
    http = service.http
    from service.db import JobDB

    db = JobDB(service.settings.db_path)
    try:
        problem = JobSpec.from_json(db.get(jid)["spec"]).to_problem()
    finally:
        db.close()
    assert pinned(problem)  # the premise of the two base fits below
    r = http.post(f"/jobs/{jid}/diagnose", json={"free_material": False}, headers=auth("alice"))
    assert r.status_code == 202, r.text
    assert r.json()["expected"] == {
        "floor_simulations": list(FLOOR_SIMULATIONS),
        "base_fits": 1,
        "catalogue_simulations": list(CATALOGUE_SIMULATIONS),
        "scaled_for": [],
    }
    assert _wait_diagnosis(http, jid, "alice", timeout=60)["state"] == "failed"
    e = http.post(f"/jobs/{jid}/diagnose", json={"candidates": ["leak"]}, headers=auth("alice")).json()["expected"]
    assert e["base_fits"] == 2 and e["floor_simulations"] == [2 * f for f in FLOOR_SIMULATIONS]
    assert e["catalogue_simulations"][1] < CATALOGUE_SIMULATIONS[1] + FLOOR_SIMULATIONS[1]
    assert any("pinned" in g for g in e["scaled_for"]) and any(g.startswith("1 of") for g in e["scaled_for"])
    assert _wait_diagnosis(http, jid, "alice", timeout=60)["state"] == "failed"


def httpx_client(srv):
    import httpx

    return httpx.Client(base_url=srv.url, timeout=60)


def _diagnosis_row(settings, jid: str) -> dict:
    from service.db import JobDB

    db = JobDB(settings.db_path)
    try:
        return db.children(jid)[0]
    finally:
        db.close()


def test_a_diagnosis_stopped_by_a_shutdown_goes_on_at_the_next_start(settings, dask_client, monkeypatch):
    """The service stops while a diagnosis runs (its cluster calls then fail): the failure is not
    recorded, the job stays running, and the next start of the service runs the same request
    again; a failure of its own is then recorded (no third start)."""
    from svc_helpers import ServerThread

    import vfcore.diagnose.pipeline as P
    from service.main import create_app

    jid = done_fe_job(settings)
    body = {
        "candidates": ["leak", "scale"],
        "n_particles": 14,
        "refit_particles": 10,
        "max_refits": 2,
        "continuation": False,
        "seed": 5,
    }
    calls = []

    def first(problem, *, map, **kw):  # runs until the service stops, then loses its cluster
        calls.append(kw)
        while True:
            try:
                map(np.square, [np.zeros((1, 1))])
            except Exception:  # noqa: BLE001 - the stop, seen by the map
                raise OSError("connection to the scheduler lost") from None
            time.sleep(0.05)

    monkeypatch.setattr(P, "diagnose", first)
    with ServerThread(create_app(settings, client=dask_client)) as srv:
        with httpx_client(srv) as http:
            assert http.post(f"/jobs/{jid}/diagnose", json=body, headers=auth("alice")).status_code == 202
            t0 = time.time()
            while not calls or http.get(f"/jobs/{jid}/diagnosis", headers=auth("alice")).json()["state"] != "running":
                assert time.time() - t0 < 30
                time.sleep(0.05)
    row = _diagnosis_row(settings, jid)
    assert row["state"] == "running" and row["error"] is None and row["attempts"] == 1

    def second(problem, *, map, **kw):
        calls.append(kw)
        raise RuntimeError("a failure of its own")

    monkeypatch.setattr(P, "diagnose", second)
    with ServerThread(create_app(settings, client=dask_client)) as srv:
        with httpx_client(srv) as http:
            d = _wait_diagnosis(http, jid, "alice", timeout=60)
    assert d["state"] == "failed" and "a failure of its own" in d["error"], d
    assert len(calls) == 2 and calls[1]["candidates"] == ["leak", "scale"]
    assert {k: calls[1][k] for k in ("n_particles", "refit_particles", "max_refits", "continuation", "seed")} == {
        "n_particles": 14,
        "refit_particles": 10,
        "max_refits": 2,
        "continuation": False,
        "seed": 5,
    }
    assert _diagnosis_row(settings, jid)["attempts"] == 2


def test_a_diagnosis_that_cannot_run_fails_and_one_stopped_too_often_is_not_started_again(settings, monkeypatch):
    """At the start of the manager: a diagnosis whose job is gone, one whose spec cannot be read and one
    interrupted MAX_AUTO_RESUMES + 1 times are recorded as failed, the last saying how to go on; none of
    them runs the diagnosis."""
    import vfcore.diagnose.pipeline as P
    from service.api_models import DiagnoseRequest, DiagnosisSpec
    from service.db import JobDB
    from service.manager import MAX_AUTO_RESUMES, JobManager

    def never(*a, **k):
        raise AssertionError("a diagnosis ran")

    monkeypatch.setattr(P, "diagnose", never)
    jid = done_fe_job(settings)
    db = JobDB(settings.db_path)
    spec = DiagnosisSpec(job=jid, request=DiagnoseRequest()).to_json()
    rows = {
        "gone": DiagnosisSpec(job="ab" * 16, request=DiagnoseRequest()).to_json(),
        "broken": "{broken",
        "stopped": spec,
    }
    ids = {}
    for name, s in rows.items():
        ids[name] = name.ljust(32, "0")
        db.insert(ids[name], "alice", s, 0, kind="diagnosis", parent=jid, sampler="smc", model="fe")
    db.update(ids["stopped"], state="running", attempts=MAX_AUTO_RESUMES + 1)
    manager = JobManager(settings, db, None)
    manager.start()
    try:
        t0 = time.time()
        while any(db.get(i)["state"] != "failed" for i in ids.values()):
            assert time.time() - t0 < 30, [db.get(i) for i in ids.values()]
            time.sleep(0.05)
    finally:
        manager.stop()
    err = {name: db.get(i)["error"] for name, i in ids.items()}
    db.close()
    assert "gone" in err["gone"] and "ValidationError" in err["broken"]
    assert (
        f"interrupted {MAX_AUTO_RESUMES + 1} times" in err["stopped"] and f"POST /jobs/{jid}/diagnose" in err["stopped"]
    )


def test_diagnoses_kept_beside_the_stores_by_an_earlier_release_become_jobs(settings):
    """The files a diagnosis left beside its job's store before diagnoses were jobs: a finished one is served as
    before (report, figure), an interrupted one is queued again with its simulations and its interruptions
    counted, a failed one keeps its error; the files are gone afterwards."""
    import json

    from test_report_diagnose import REPORT

    from service.db import JobDB
    from service.manager import JobManager

    done, stopped, failed = (done_fe_job(settings) for _ in range(3))
    d = settings.stores_dir
    (d / f"{done}.diagnosis.json").write_text(json.dumps(REPORT))
    (d / f"{done}.diagnosis.png").write_bytes(b"\x89PNG\r\n\x1a\nold")
    (d / f"{stopped}.diagnosis.request.json").write_text(json.dumps({"request": {"n_particles": 14}, "resumes": 1}))
    (d / f"{stopped}.diagnosis.resume" / "x").mkdir(parents=True)
    (d / f"{failed}.diagnosis.error").write_text("RuntimeError: old failure")
    db = JobDB(settings.db_path)
    manager = JobManager(settings, db, None)
    from service.diagnosis_import import import_legacy_diagnoses

    made = import_legacy_diagnoses(manager)
    rows = {r["parent"]: r for r in db.list(kind="diagnosis")}
    db.close()
    assert len(made) == 3 and set(rows) == {done, stopped, failed}
    assert not list(d.glob("*.diagnosis.*"))
    from service.diagnosis import read_report
    from worker.store import read_blob

    r = rows[done]
    assert r["state"] == "done" and r["owner"] == "alice"
    rep = read_report(d / f"{r['id']}.zarr", r["stats"], REPORT["request"])
    assert rep == json.loads(json.dumps(REPORT))
    assert read_blob(d / f"{r['id']}.zarr", "diagnosis_png") == b"\x89PNG\r\n\x1a\nold"
    r = rows[stopped]
    assert r["state"] == "running" and r["attempts"] == 2 and json.loads(r["spec"])["request"]["n_particles"] == 14
    assert (d / f"{r['id']}.zarr" / "resume" / "x").is_dir()
    assert rows[failed]["state"] == "failed" and rows[failed]["error"] == "RuntimeError: old failure"


def test_a_running_diagnosis_can_be_cancelled(settings, dask_client, monkeypatch):
    """DELETE /jobs/{id}/diagnosis (and DELETE /jobs/{diagnosis_id}, as for any job) stops a running
    diagnosis at its next batch: its state becomes "cancelled", its stored simulations are deleted, a second
    DELETE is a 409, another user's is a 404, and a new POST starts afresh."""
    import threading

    from svc_helpers import ServerThread

    import vfcore.diagnose.pipeline as P
    from service.main import create_app

    jid = done_fe_job(settings)
    batches = []
    started = threading.Event()

    def endless(problem, *, map, **kw):  # batch after batch through the service's map
        for k in range(100_000):
            map(np.square, [np.full((2, 1), float(k)), np.full((2, 1), -float(k))])
            batches.append(k)
            started.set()
            time.sleep(0.02)
        raise AssertionError("never cancelled")

    monkeypatch.setattr(P, "diagnose", endless)
    d = settings.stores_dir

    def cancelled_by(http, delete) -> None:
        batches.clear()
        started.clear()
        r = http.post(f"/jobs/{jid}/diagnose", json={"continuation": False}, headers=auth("alice"))
        assert r.status_code == 202, r.text
        diag = r.json()["diagnosis_id"]
        assert started.wait(60)
        assert (d / f"{diag}.zarr" / "resume").exists()
        assert http.delete(f"/jobs/{jid}/diagnosis", headers=auth("bob")).status_code == 404
        assert http.delete(f"/jobs/{diag}", headers=auth("bob")).status_code == 404
        delete(diag)
        t0 = time.time()
        while (st := http.get(f"/jobs/{jid}/diagnosis", headers=auth("alice")).json())["state"] == "running":
            assert time.time() - t0 < 60
            time.sleep(0.1)
        assert st["state"] == "cancelled" and st["diagnosis_id"] == diag, st
        n = len(batches)
        time.sleep(0.3)
        assert len(batches) == n  # it stopped
        assert not (d / f"{diag}.zarr" / "resume").exists()
        assert http.delete(f"/jobs/{jid}/diagnosis", headers=auth("alice")).status_code == 409

    with ServerThread(create_app(settings, client=dask_client)) as srv:
        with httpx_client(srv) as http:
            assert http.delete(f"/jobs/{jid}/diagnosis", headers=auth("alice")).status_code == 409  # none running

            def by_the_diagnosis_route(diag):
                r = http.delete(f"/jobs/{jid}/diagnosis", headers=auth("alice"))
                assert r.status_code == 202 and r.json()["state"] == "cancelling", r.text
                assert r.json()["diagnosis_id"] == diag

            def by_the_job_route(diag):
                r = http.delete(f"/jobs/{diag}", headers=auth("alice"))
                assert r.status_code == 200 and r.json() == {"id": diag, "state": "cancelled"}, r.text

            cancelled_by(http, by_the_diagnosis_route)
            cancelled_by(http, by_the_job_route)

            def fails(problem, *, map, **kw):
                raise RuntimeError("second run")

            monkeypatch.setattr(P, "diagnose", fails)
            assert (
                http.post(f"/jobs/{jid}/diagnose", json={"continuation": False}, headers=auth("alice")).status_code
                == 202
            )
            st = _wait_diagnosis(http, jid, "alice", timeout=60)
            assert st["state"] == "failed" and "second run" in st["error"]  # the cancelled mark is gone
