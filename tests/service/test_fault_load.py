"""A worker process killed mid-job; 20 concurrent submissions from several tokens."""

from __future__ import annotations

import os
import signal
import threading
import time

import numpy as np
import pytest
from svc_helpers import TOKENS, auth, toy_spec, wait_done

from worker import store as st


def _posterior_bytes(service, job_id, user):
    http = service.http
    post = http.get(f"/jobs/{job_id}/posterior", headers=auth(user)).json()
    post.pop("id")
    arrs = st.read_posterior_arrays(service.settings.stores_dir / f"{job_id}.zarr")
    return post, {k: v.tobytes() for k, v in arrs.items()}


def _kill_busy_worker(client) -> str:
    t0 = time.time()
    while time.time() - t0 < 20:
        busy = [w for w, tasks in client.processing().items() if any("vfchunk" in str(k) for k in tasks)]
        if busy:
            pid = client.run(os.getpid, workers=[busy[0]])[busy[0]]
            os.kill(pid, signal.SIGKILL)  # the worker process dies mid-chunk
            return busy[0]
        time.sleep(0.02)
    raise AssertionError("no busy worker found")


def test_worker_killed_mid_job_bit_identical(service):
    http, client = service.http, service.client
    spec = toy_spec(n=480, seed=21, delay=0.01, chunk_size=24)  # 20 chunks of ~0.24 s
    ref = http.post("/jobs", json=spec, headers=auth("alice")).json()["id"]
    assert wait_done(http, ref, "alice")["state"] == "done"
    n_workers = len(client.scheduler_info()["workers"])

    job = http.post("/jobs", json=spec, headers=auth("alice")).json()["id"]
    t0 = time.time()
    while http.get(f"/jobs/{job}", headers=auth("alice")).json()["progress"]["simulations_done"] < 100:
        assert time.time() - t0 < 60
        time.sleep(0.02)
    killed = _kill_busy_worker(client)
    st_ = wait_done(http, job, "alice", timeout=120)
    assert st_["state"] == "done", st_
    assert killed not in client.scheduler_info()["workers"]  # that process really went away
    a, b = _posterior_bytes(service, ref, "alice"), _posterior_bytes(service, job, "alice")
    assert a[1] == b[1]  # samples, log-weights, resampled indices: same bytes
    assert a[0] == b[0]  # the published summary too
    client.wait_for_workers(n_workers, timeout=60)  # the nanny restarted it


# A load test (20 jobs through one service): about a minute on 2 cores, so `make test-all` runs it.
@pytest.mark.slow
def test_twenty_concurrent_submissions_and_fast_status(service):
    from toy_model import ToyEvaluator

    from vfcore.inference.importance import importance_sample
    from worker.jobspec import JobSpec

    http_url = service.url
    users = list(TOKENS)
    specs = [toy_spec(n=240, seed=100 + i, delay=0.004) for i in range(20)]
    ids: list = [None] * 20
    codes: list = [None] * 20

    def submit(i):
        import httpx

        with httpx.Client(base_url=http_url, timeout=60) as h:
            r = h.post("/jobs", json=specs[i], headers=auth(users[i % 3]))
            codes[i] = r.status_code
            ids[i] = r.json().get("id")

    threads = [threading.Thread(target=submit, args=(i,)) for i in range(20)]
    t_start = time.time()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert codes == [202] * 20
    # status latency while the cluster is busy
    lat = []
    http = service.http
    while True:
        states = []
        for i, jid in enumerate(ids):
            t0 = time.perf_counter()
            r = http.get(f"/jobs/{jid}", headers=auth(users[i % 3]))
            lat.append(time.perf_counter() - t0)
            states.append(r.json()["state"])
        if all(s in ("done", "failed", "cancelled") for s in states):
            break
        assert time.time() - t_start < 180
    wall = time.time() - t_start
    assert states == ["done"] * 20
    lat_ms = np.array(lat) * 1e3
    p50, p95 = np.percentile(lat_ms, [50, 95])
    print(
        f"\n20 jobs x 240 sims: wall {wall:.1f} s; status latency over {lat_ms.size} calls while busy: "
        f"p50 {p50:.1f} ms, p95 {p95:.1f} ms, max {lat_ms.max():.1f} ms"
    )
    # Not a speed target (those live in benchmarks/bench_service.py --status-load, which prints the
    # p95 against its 250 ms target): a status read must not wait for the work it reports on, so
    # its latency is a small fraction of the batch's wall time, however loaded the machine is.
    assert p95 < 0.1 * wall * 1e3, f"status p95 {p95:.0f} ms against a {wall:.1f} s batch"
    # each user sees exactly their own jobs
    for u in users:
        mine = {j["id"] for j in http.get("/jobs", headers=auth(u)).json()}
        assert mine == {ids[i] for i in range(20) if users[i % 3] == u}
    # every job is correct: equal to vfcore called directly with the same seed
    for i in (0, 7, 13, 19):
        s = JobSpec.model_validate(specs[i])
        pb = s.to_problem()
        direct = importance_sample(ToyEvaluator(pb), pb.prior, 240, s.seed)
        js = http.get(f"/jobs/{ids[i]}/samples", params={"format": "json"}, headers=auth(users[i % 3])).json()
        np.testing.assert_array_equal(np.array(js["samples"]), direct.samples)
        np.testing.assert_array_equal(np.array(js["resampled"]), direct.resampled)
