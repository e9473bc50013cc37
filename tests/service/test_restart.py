"""The whole service (API + its LocalCluster) killed mid-job and restarted: the job resumes from
its store, finished chunks are not recomputed, and the posterior equals an undisturbed run."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import zarr

from svc_helpers import TOKENS, auth, free_port, toy_spec, wait_done

ROOT = Path(__file__).resolve().parents[2]


def _start(data_dir: Path, port: int) -> subprocess.Popen:
    env = {**os.environ, "VFINFER_DATA_DIR": str(data_dir), "VFINFER_ALLOW_TOY": "1", "VFINFER_N_WORKERS": "2",
           "VFINFER_TOKENS": ",".join(f"{u}:{t}" for u, t in TOKENS.items()), "OMP_NUM_THREADS": "1"}
    log = data_dir.parent / f"serve_{port}_{time.time_ns()}.log"       # kept for the error message
    with open(log, "wb") as fh:
        p = subprocess.Popen([sys.executable, "-m", "service.cli", "serve", "--port", str(port)], cwd=ROOT, env=env,
                             stdout=fh, stderr=subprocess.STDOUT, start_new_session=True)
    t0 = time.time()
    while True:
        try:
            if httpx.get(f"http://127.0.0.1:{port}/health", timeout=1).json()["dask_workers"] == 2:
                return p
        except (httpx.HTTPError, KeyError, ValueError):
            pass
        if time.time() - t0 > 180 or p.poll() is not None:
            rc = p.poll()
            _kill(p)
            tail = log.read_text(errors="replace")[-3000:]
            raise RuntimeError(f"service did not start on port {port} within {time.time() - t0:.0f} s "
                               f"(exit code {rc}); its output:\n{tail}")
        time.sleep(0.2)


def _kill(p: subprocess.Popen) -> None:
    """SIGKILL the service and every process it started (its LocalCluster): a host crash."""
    try:
        os.killpg(p.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    p.wait(30)


def test_service_restart_resumes_without_recomputing(tmp_path):
    from vfcore.inference.importance import importance_sample
    from worker.jobspec import JobSpec
    from worker.toy import ToyEvaluator

    data = tmp_path / "data"
    port = free_port()
    spec = toy_spec(n=600, seed=33, delay=0.01, chunk_size=30)       # 20 chunks of ~0.3 s
    p = _start(data, port)
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=30) as http:
            job = http.post("/jobs", json=spec, headers=auth("bob")).json()["id"]
            t0 = time.time()
            while http.get(f"/jobs/{job}", headers=auth("bob")).json()["progress"]["simulations_done"] < 200:
                assert time.time() - t0 < 60
                time.sleep(0.05)
    finally:
        _kill(p)
    store = data / "stores" / f"{job}.zarr"
    done_before = np.asarray(zarr.open_group(str(store), mode="r")["batches/0/done"][...])
    assert 0 < done_before.sum() < done_before.size
    p = _start(data, port)
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
        _kill(p)
    s = JobSpec.model_validate(spec)
    pb = s.to_problem()
    direct = importance_sample(ToyEvaluator(pb), pb.prior, 600, s.seed)
    np.testing.assert_array_equal(np.array(js["samples"]), direct.samples)
    np.testing.assert_array_equal(np.array(js["resampled"]), direct.resampled)
