"""The whole service (API + its LocalCluster) killed mid-job and restarted: the job resumes from
its store, finished chunks are not recomputed, and the posterior equals an undisturbed run."""

from __future__ import annotations

import time

import httpx
import numpy as np
import zarr
from svc_helpers import auth, kill_service, start_service, toy_spec, wait_done


def test_service_restart_resumes_without_recomputing(tmp_path):
    from toy_model import ToyEvaluator

    from vfcore.inference.importance import importance_sample
    from worker.jobspec import JobSpec

    data = tmp_path / "data"
    spec = toy_spec(n=600, seed=33, delay=0.01, chunk_size=30)  # 20 chunks of ~0.3 s
    p, port = start_service(data)
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=30) as http:
            job = http.post("/jobs", json=spec, headers=auth("bob")).json()["id"]
            t0 = time.time()
            while http.get(f"/jobs/{job}", headers=auth("bob")).json()["progress"]["simulations_done"] < 200:
                assert time.time() - t0 < 60
                time.sleep(0.05)
    finally:
        kill_service(p)
    store = data / "stores" / f"{job}.zarr"
    done_before = np.asarray(zarr.open_group(str(store), mode="r")["batches/0/done"][...])
    assert 0 < done_before.sum() < done_before.size
    p, port = start_service(data)
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=30) as http:
            st = wait_done(http, job, "bob", timeout=120)
            assert st["state"] == "done", st
            last = st["stats"]["runs"][-1]
            assert last["chunks_skipped"] == int(done_before.sum())
            assert last["chunks_computed"] == done_before.size - int(done_before.sum())
            assert st["progress"]["simulations_done"] == 600
            js = http.get(f"/jobs/{job}/samples", params={"format": "json"}, headers=auth("bob")).json()
            assert http.get(f"/jobs/{job}", headers=auth("alice")).status_code == 404
    finally:
        kill_service(p)
    s = JobSpec.model_validate(spec)
    pb = s.to_problem()
    direct = importance_sample(ToyEvaluator(pb), pb.prior, 600, s.seed)
    np.testing.assert_array_equal(np.array(js["samples"]), direct.samples)
    np.testing.assert_array_equal(np.array(js["resampled"]), direct.resampled)
