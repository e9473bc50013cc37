"""POST /jobs/{id}/diagnose, GET /jobs/{id}/diagnosis(/figure): ownership, states, validation, and one
real (tiny) diagnosis of a finished finite-element job on the service's Dask cluster."""
from __future__ import annotations

import time

import numpy as np
import pytest

from svc_helpers import auth, dying_diagnosis, toy_spec, wait_done

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
    manager = SimpleNamespace(store_path=lambda jid: tmp_path / f"{jid}.zarr", client=None)
    spec = SimpleNamespace(to_problem=lambda: None)
    _run(manager, _Registry(), "j1", spec, DiagnoseRequest(continuation=False))
    assert "worker lost" in (tmp_path / "j1.diagnosis.error").read_text()
    assert len(list(resume_store(manager, "j1").rglob("*.pkl"))) == 3
    _run(manager, _Registry(), "j1", spec, DiagnoseRequest(continuation=False))
    assert (maps[1].hits, maps[1].misses) == (3, 0)
    assert maps[1].earlier_attempts == 1                  # the dead attempt's time is on record
