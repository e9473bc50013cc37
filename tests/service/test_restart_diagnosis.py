"""The whole service (API + its LocalCluster) killed during a diagnosis and restarted: the diagnosis resumes from
its store, reading back the simulations it had finished, and stores the same report and figure, byte for byte,
as an uninterrupted diagnosis of the same job with the same settings.

Fast (~40 s on 2 cores, most of it two service starts): the diagnosis is a deterministic stand-in evaluated
through the service's map (``serve_stand_in_diagnosis.py``). Slow (~100 s): the real diagnosis of a tiny FE job at
the smallest settings the endpoint tests use (refit particles at vfcore's SMC floor of 10), 890 simulations, the
service killed 300 simulations in."""

from __future__ import annotations

import time
from pathlib import Path

import httpx
import pytest
from svc_helpers import auth, done_fe_job, kill_service, leaky_fe_spec, start_service

HERE = Path(__file__).resolve().parent
STAND_IN = {
    "script": [str(HERE / "serve_stand_in_diagnosis.py")],
    "body": {"seed": 3, "continuation": False},
    "kill_at": 8 * 12,
    "timeout": 120,
}
REAL = {
    "script": None,
    "kill_at": 300,
    "timeout": 1800,
    "body": {
        "candidates": ["leak"],
        "n_particles": 12,
        "refit_particles": 10,
        "max_refits": 1,
        "seed": 0,
        "continuation": False,
        "free_material": False,
    },
}


def _wait(http, job: str, timeout: float, until=lambda d: d["state"] not in ("queued", "running")) -> dict:
    t0 = time.time()
    while not until(d := http.get(f"/jobs/{job}/diagnosis", headers=auth("alice")).json()):
        assert time.time() - t0 < timeout, d
        time.sleep(0.1)
    return d


@pytest.mark.parametrize(
    "case", [pytest.param(STAND_IN, id="stand-in"), pytest.param(REAL, id="real", marks=pytest.mark.slow)]
)
def test_a_restart_during_a_diagnosis_resumes_it_and_stores_the_same_report_bytes(tmp_path, case):
    from service.diagnosis import report_bytes, resume_dir
    from service.settings import Settings
    from worker.store import read_blob

    data = tmp_path / "data"
    settings = Settings(data_dir=data)
    spec = leaky_fe_spec() if case is REAL else None
    interrupted, uninterrupted = (done_fe_job(settings, spec=spec) for _ in range(2))
    p, port = start_service(data, script=case["script"])
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=30) as http:
            r = http.post(f"/jobs/{interrupted}/diagnose", json=case["body"], headers=auth("alice"))
            assert r.status_code == 202, r.text
            diag = r.json()["diagnosis_id"]
            first = _wait(
                http,
                interrupted,
                case["timeout"],
                until=lambda d: (
                    (d["progress"] or {}).get("simulations", 0) >= case["kill_at"]
                    or d["state"] not in ("queued", "running")
                ),
            )
    finally:
        kill_service(p)
    assert first["state"] == "running", first
    kept = len(list(resume_dir(data / "stores" / f"{diag}.zarr").rglob("*.pkl")))
    assert kept > 0 and report_bytes(data / "stores" / f"{diag}.zarr") is None  # killed in the middle
    p, port = start_service(data, script=case["script"])
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=30) as http:
            resumed = _wait(http, interrupted, case["timeout"])
            assert resumed["state"] == "done" and resumed["diagnosis_id"] == diag, resumed
            r = http.post(f"/jobs/{uninterrupted}/diagnose", json=case["body"], headers=auth("alice"))
            assert r.status_code == 202, r.text
            whole = _wait(http, uninterrupted, case["timeout"])
            assert whole["state"] == "done", whole
            st = http.get(f"/jobs/{diag}", headers=auth("alice")).json()
    finally:
        kill_service(p)
    assert st["kind"] == "diagnosis" and st["parent"] == interrupted and st["state"] == "done"
    a, b = (data / "stores" / f"{d['diagnosis_id']}.zarr" for d in (resumed, whole))
    assert report_bytes(a) == report_bytes(b) and report_bytes(a)
    assert read_blob(a, "diagnosis_png") == read_blob(b, "diagnosis_png")
    ra, rb = resumed["report"]["resume_store"], whole["report"]["resume_store"]
    assert ra["earlier_attempts"] == 1 and ra["parts_read"] == kept  # read back, not simulated again
    assert ra["parts_simulated"] > 0  # and the rest simulated
    assert rb["earlier_attempts"] == 0 and rb["parts_read"] == 0
    assert ra["parts_read"] + ra["parts_simulated"] == rb["parts_simulated"]
    assert resumed["report"]["n_simulations"] == whole["report"]["n_simulations"]
    assert not resume_dir(a).exists() and not resume_dir(b).exists()
