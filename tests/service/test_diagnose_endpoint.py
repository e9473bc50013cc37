"""POST /jobs/{id}/diagnose, GET /jobs/{id}/diagnosis(/figure): ownership, states, validation, and one
real (tiny) diagnosis of a finished finite-element job on the service's Dask cluster."""
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
        assert d["state"] == "running", d
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
    for method, path in (("post", f"/jobs/{toy}/diagnose"), ("get", f"/jobs/{toy}/diagnosis"),
                         ("get", f"/jobs/{toy}/diagnosis/figure")):
        assert getattr(http, method)(path, headers=auth("bob")).status_code == 404, path
    assert http.get(f"/jobs/{'x' * 32}/diagnosis", headers=auth("alice")).status_code == 404
    r = http.post(f"/jobs/{toy}/diagnose", headers=auth("alice"))
    assert r.status_code == 422 and "fe" in r.text, r.text
    # nothing ever started on it
    assert http.get(f"/jobs/{toy}/diagnosis", headers=auth("alice")).json() == \
        {"state": "none", "error": None, "report": None, "progress": None}
    assert http.get(f"/jobs/{toy}/diagnosis/figure", headers=auth("alice")).status_code == 404
    # body validation: unknown / unimplemented candidates are named, ranges enforced, extras refused
    r = http.post(f"/jobs/{toy}/diagnose", json={"candidates": ["leak", "warp_drive"]}, headers=auth("alice"))
    assert r.status_code == 422 and "warp_drive" in r.text and "leak'" not in r.text.split("known")[0], r.text
    for body in ({"n_particles": 5}, {"n_particles": 401}, {"max_refits": 7}, {"refit_particles": 3}, {"candidates": []},
                 {"colour": "red"}):
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
    from vfcore import TABLE3, SimConfig, simulate
    cfg = dict(mesh="coarse", dt=1e-4, duration=0.35, discard=0.15)
    r = simulate(TABLE3, SimConfig(fps=FPS, **cfg))
    assert r.ok, r.message
    y = np.clip(r.gaw + 1.5 + np.random.default_rng(3).normal(0.0, 0.3, r.gaw.size), 0.0, None)
    fixed = {k: v for k, v in TABLE3.as_dict().items() if k != "E_cover"}
    return {"model": "fe", "gaw": {"areas": [float(a) for a in y], "fps": FPS, "units": "mm2"},
            "fixed": fixed, "sampler": {"kind": "is", "n_samples": 16}, "sigma_e": 1.0, "seed": 1,
            "chunk_size": 8, **cfg}


@pytest.mark.slow
def test_diagnose_finished_fe_job(service, leaky_spec):
    http = service.http
    r = http.post("/jobs", json=leaky_spec, headers=auth("alice"))
    assert r.status_code == 202, r.text
    job = r.json()["id"]
    assert wait_done(http, job, "alice", timeout=300)["state"] == "done"

    body = {"candidates": ["leak"], "n_particles": 12, "max_refits": 1, "seed": 0,
            "continuation": False}          # the search itself: tests/vfcore/test_diagnose_search.py
    t0 = time.perf_counter()
    r = http.post(f"/jobs/{job}/diagnose", json=body, headers=auth("alice"))
    assert r.status_code == 202, r.text
    assert r.json()["status_url"] == f"/jobs/{job}/diagnosis"
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
    assert rep["winner"] == "leak", rep["verdict"]          # the hidden 1.5 mm^2 leak is found
    assert rep["n_simulations"] > 0 and rep["base"]["residual_rms"] > 0
    assert set(rep["screening"]) >= {"leak"} and rep["request"]["n_particles"] == 12
    assert rep["wall_s"] <= wall + 1.0
    assert rep["resume_store"]["earlier_attempts"] == 0 and rep["resume_store"]["parts_simulated"] > 0
    fig = http.get(f"/jobs/{job}/diagnosis/figure", headers=auth("alice"))
    assert fig.status_code == 200 and fig.headers["content-type"] == "image/png"
    assert fig.content[:8] == b"\x89PNG\r\n\x1a\n"
    assert http.get(f"/jobs/{job}/diagnosis/figure", headers=auth("bob")).status_code == 404
    # no temporary files left next to the store
    stores = service.settings.stores_dir
    assert not [p.name for p in stores.iterdir() if p.name.startswith(".")]
    assert (stores / f"{job}.diagnosis.json").exists() and (stores / f"{job}.diagnosis.png").exists()
    assert not (stores / f"{job}.diagnosis.resume").exists()      # the resume store goes once done


def test_an_interrupted_diagnosis_is_resumed_from_its_store(tmp_path, monkeypatch):
    """The diagnosis thread's body, with the diagnosis replaced by one that evaluates 3 parts and
    then dies: the failure is recorded, the 3 parts stay in <id>.diagnosis.resume, and the same
    request started again reads all 3 back and simulates nothing."""
    from types import SimpleNamespace

    import vfcore.diagnose.pipeline as P
    from service.routers.diagnose import DiagnoseRequest, _Registry, _run, resume_store

    maps = []
    monkeypatch.setattr(P, "diagnose", dying_diagnosis(maps, "worker lost"))
    manager = SimpleNamespace(settings=SimpleNamespace(stores_dir=tmp_path), store_path=lambda jid: tmp_path / f"{jid}.zarr", client=None)
    spec = SimpleNamespace(to_problem=lambda: None)
    _run(manager, _Registry(), "j1", spec, DiagnoseRequest(continuation=False))
    assert "worker lost" in (tmp_path / "j1.diagnosis.error").read_text()
    assert len(list(resume_store(manager, "j1").rglob("*.pkl"))) == 3
    _run(manager, _Registry(), "j1", spec, DiagnoseRequest(continuation=False))
    store = maps[1].inner                                 # the store, inside the cancellable map
    assert (store.hits, store.misses) == (3, 0)
    assert store.earlier_attempts == 1                    # the dead attempt's time is on record


def httpx_client(srv):
    import httpx
    return httpx.Client(base_url=srv.url, timeout=60)


def test_a_diagnosis_stopped_by_a_shutdown_goes_on_at_the_next_start(settings, dask_client, monkeypatch):
    """The service stops while a diagnosis runs (its cluster calls then fail): the failure is not
    recorded, the request stays on disk, and the next start of the service runs the same request
    again; a failure of its own is then recorded, and the request is gone (no third start)."""
    import threading

    import vfcore.diagnose.pipeline as P
    from service.main import create_app
    from svc_helpers import ServerThread

    jid = done_fe_job(settings)
    body = {"candidates": ["leak", "scale"], "n_particles": 14, "refit_particles": 6, "max_refits": 2,
            "continuation": False, "seed": 5}
    gate, entered, calls = threading.Event(), threading.Event(), []

    def first(problem, *, map, **kw):          # runs until the service stops, then loses its cluster
        calls.append(kw)
        entered.set()
        gate.wait(30)
        raise OSError("connection to the scheduler lost")

    monkeypatch.setattr(P, "diagnose", first)
    request_file = settings.stores_dir / f"{jid}.diagnosis.request.json"
    with ServerThread(create_app(settings, client=dask_client)) as srv:
        with httpx_client(srv) as http:
            assert http.post(f"/jobs/{jid}/diagnose", json=body, headers=auth("alice")).status_code == 202
            assert entered.wait(30)
            assert http.get(f"/jobs/{jid}/diagnosis", headers=auth("alice")).json()["state"] == "running"
            assert request_file.exists()
    gate.set()                                  # the shutdown has happened: now the thread fails
    for t in threading.enumerate():
        if t.name.startswith(f"vfinfer-diagnose-{jid[:8]}"):
            t.join(30)
    assert request_file.exists() and not (settings.stores_dir / f"{jid}.diagnosis.error").exists()

    def second(problem, *, map, **kw):
        calls.append(kw)
        raise RuntimeError("a failure of its own")

    monkeypatch.setattr(P, "diagnose", second)
    with ServerThread(create_app(settings, client=dask_client)) as srv:
        with httpx_client(srv) as http:
            d = _wait_diagnosis(http, jid, "alice", timeout=60)
    assert d["state"] == "failed" and "a failure of its own" in d["error"], d
    assert len(calls) == 2 and calls[1]["candidates"] == ["leak", "scale"]
    assert {k: calls[1][k] for k in ("n_particles", "refit_particles", "max_refits", "continuation", "seed")} == \
        {"n_particles": 14, "refit_particles": 6, "max_refits": 2, "continuation": False, "seed": 5}
    assert not request_file.exists()


def test_resume_pending_drops_what_it_cannot_run_and_gives_up_after_repeated_stops(settings, monkeypatch):
    """A request whose job is gone is dropped with its store; one interrupted MAX_AUTO_RESUMES times
    becomes a failure saying how to go on; an unreadable one is dropped; none of them starts."""
    import json
    from types import SimpleNamespace

    from service.db import JobDB
    from service.routers.diagnose import MAX_AUTO_RESUMES, _Registry, resume_pending

    jid = done_fe_job(settings)
    gone = "ab" * 16
    d = settings.stores_dir
    (d / f"{gone}.diagnosis.request.json").write_text(json.dumps({"request": {}, "resumes": 0}))
    (d / f"{gone}.diagnosis.resume").mkdir()
    (d / f"{jid}.diagnosis.request.json").write_text(json.dumps({"request": {}, "resumes": MAX_AUTO_RESUMES}))
    (d / f"{'cd' * 16}.diagnosis.request.json").write_text("{broken")
    db = JobDB(settings.db_path)
    manager = SimpleNamespace(settings=settings, store_path=lambda j: d / f"{j}.zarr", db=db, client=None)
    reg = _Registry()
    assert resume_pending(manager, reg) == [] and not reg.running
    db.close()
    assert not list(d.glob("*.diagnosis.request.json")) and not (d / f"{gone}.diagnosis.resume").exists()
    err = (d / f"{jid}.diagnosis.error").read_text()
    assert f"interrupted {MAX_AUTO_RESUMES + 1} times" in err and f"POST /jobs/{jid}/diagnose" in err


def test_a_running_diagnosis_can_be_cancelled(settings, dask_client, monkeypatch):
    """DELETE /jobs/{id}/diagnosis stops a running diagnosis at its next batch: its state becomes
    "cancelled", its stored simulations and request are deleted, a second DELETE is a 409, another
    user's is a 404, and a new POST starts afresh."""
    import threading

    import vfcore.diagnose.pipeline as P
    from service.main import create_app
    from svc_helpers import ServerThread

    jid = done_fe_job(settings)
    batches = []
    started = threading.Event()

    def endless(problem, *, map, **kw):         # batch after batch through the service's map
        for k in range(100_000):
            map(np.square, [np.full((2, 1), float(k)), np.full((2, 1), -float(k))])
            batches.append(k)
            started.set()
            time.sleep(0.02)
        raise AssertionError("never cancelled")

    monkeypatch.setattr(P, "diagnose", endless)
    d = settings.stores_dir
    with ServerThread(create_app(settings, client=dask_client)) as srv:
        with httpx_client(srv) as http:
            assert http.delete(f"/jobs/{jid}/diagnosis", headers=auth("alice")).status_code == 409   # none running
            assert http.post(f"/jobs/{jid}/diagnose", json={"continuation": False}, headers=auth("alice")).status_code == 202
            assert started.wait(60)
            assert (d / f"{jid}.diagnosis.resume").exists()
            assert http.delete(f"/jobs/{jid}/diagnosis", headers=auth("bob")).status_code == 404
            r = http.delete(f"/jobs/{jid}/diagnosis", headers=auth("alice"))
            assert r.status_code == 202 and r.json()["state"] == "cancelling", r.text
            t0 = time.time()
            while (st := http.get(f"/jobs/{jid}/diagnosis", headers=auth("alice")).json())["state"] == "running":
                assert time.time() - t0 < 60
                time.sleep(0.1)
            assert st["state"] == "cancelled", st
            n = len(batches)
            time.sleep(0.3)
            assert len(batches) == n                    # it stopped
            assert not (d / f"{jid}.diagnosis.resume").exists()
            assert not (d / f"{jid}.diagnosis.request.json").exists()
            assert http.delete(f"/jobs/{jid}/diagnosis", headers=auth("alice")).status_code == 409

            def fails(problem, *, map, **kw):
                raise RuntimeError("second run")
            monkeypatch.setattr(P, "diagnose", fails)
            assert http.post(f"/jobs/{jid}/diagnose", json={"continuation": False}, headers=auth("alice")).status_code == 202
            st = _wait_diagnosis(http, jid, "alice", timeout=60)
            assert st["state"] == "failed" and "second run" in st["error"]     # the cancelled mark is gone
