"""The deployed shape of docker-compose.yml, without Docker: a `dask scheduler`, two `dask worker`
processes and `vfinfer serve` as separate OS processes on 127.0.0.1, started with the commands and
environment the compose file gives them (only hosts, ports and the data path are made local).

A job run there is byte-identical to the same job on the in-process LocalCluster the rest of the
suite uses, and stays so when one worker "container" is SIGKILLed mid-job; a structural test pins the
parts of the compose file that the distributed code path relies on."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import httpx
import numpy as np
import pytest
import yaml
import zarr
from svc_helpers import TOKENS, auth, listening_port, toy_spec, wait_done
from toy_model import PLUGIN_ENV

from worker import store as st

ROOT = Path(__file__).resolve().parents[2]
COMPOSE = ROOT / "docker-compose.yml"
BIN = Path(sys.executable).parent
DASK = BIN / "dask"
VFINFER = BIN / "vfinfer"

# 20 chunks of ~0.48 s (the toy model sleeps, so two workers progress in parallel even on a busy
# 2-core machine): long enough that a kill lands mid-job, short enough for a ~5 s job.
SPEC = toy_spec(n=480, seed=21, delay=0.02, chunk_size=24)


def _compose() -> dict:
    return yaml.safe_load(COMPOSE.read_text())


def _volume(entry: str) -> tuple[str, str]:
    """'name:/path[:mode]' -> (name, /path)."""
    name, path, *_ = entry.split(":")
    return name, path


def _depends(svc: dict) -> set[str]:
    dep = svc.get("depends_on") or []
    return set(dep) if isinstance(dep, (list, dict)) else set()


def _arg(cmd: list[str], flag: str) -> str:
    return cmd[cmd.index(flag) + 1]


# ------------------------------------------------------------------------------ structural test
def test_compose_file_wires_scheduler_workers_and_api_together():
    doc = _compose()
    svcs = doc["services"]
    assert {"scheduler", "worker", "api"} <= set(svcs)
    sch, wrk, api = svcs["scheduler"], svcs["worker"], svcs["api"]

    sch_cmd, wrk_cmd, api_cmd = sch["command"], wrk["command"], api["command"]
    assert sch_cmd[:2] == ["dask", "scheduler"]
    port = _arg(sch_cmd, "--port")
    assert port == "8786"
    address = f"tcp://scheduler:{port}"

    assert wrk_cmd[:2] == ["dask", "worker"]
    assert address in wrk_cmd  # workers find the scheduler service
    # one thread per worker process: results are bit-identical only with one BLAS/numba thread
    assert _arg(wrk_cmd, "--nthreads") == "1"
    assert api_cmd[:2] == ["vfinfer", "serve"]

    api_env = api["environment"]
    assert api_env["VFINFER_SCHEDULER"] == address  # the API submits where workers listen

    # workers write the Zarr stores the API reads: one named volume, mounted at one path everywhere
    mounts = {name: {_volume(v) for v in svcs[name].get("volumes", [])} for name in ("scheduler", "worker", "api")}
    assert len(mounts["api"]) == 1, mounts
    assert mounts["scheduler"] == mounts["worker"] == mounts["api"], mounts
    ((vol_name, vol_path),) = mounts["api"]
    assert vol_path == api_env["VFINFER_DATA_DIR"]
    assert vol_name in (doc.get("volumes") or {})  # a named volume, not a host bind

    assert "scheduler" in _depends(wrk)
    assert "scheduler" in _depends(api)
    # workers and API wait for the scheduler's healthcheck, which must probe the port its HTTP
    # server (the dashboard address) listens on, or they would never start
    dash_port = _arg(sch_cmd, "--dashboard-address").rsplit(":", 1)[1]
    assert f"localhost:{dash_port}/health" in " ".join(sch["healthcheck"]["test"])
    assert f"localhost:{_arg(api_cmd, '--port')}/health" in " ".join(api["healthcheck"]["test"])

    # a lost worker's chunks are retried, not failed: the scheduler reads this (the fault test
    # below sets it the same way), and the processes keep one math thread each
    for name in ("scheduler", "worker", "api"):
        env = svcs[name]["environment"]
        assert int(env["DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES"]) >= 1, name
        assert env["OMP_NUM_THREADS"] == env["OPENBLAS_NUM_THREADS"] == env["NUMBA_NUM_THREADS"] == "1", name


# ------------------------------------------------------------------------------ process cluster
def _local(cmd: list[str], values: dict[str, str], replace: dict[str, str] | None = None) -> list[str]:
    """A compose command made runnable here: console scripts from this venv, flag values and
    positional arguments swapped for local ones; every other flag stays as compose has it."""
    out = list(cmd)
    for flag, value in values.items():
        out[out.index(flag) + 1] = value
    out = [(replace or {}).get(a, a) for a in out]
    if out[0] == "dask":
        return [str(DASK), *out[1:]]
    if out[0] == "vfinfer":
        return [str(VFINFER), *out[1:]] if VFINFER.exists() else [sys.executable, "-m", "service.cli", *out[1:]]
    raise AssertionError(f"unexpected entry point {out[0]!r}")


def _env(compose_env: dict, **local) -> dict[str, str]:
    # the test double's module for the workers (unpickling its evaluator) and the API (its registry)
    env = {**os.environ, **{k: str(v) for k, v in compose_env.items()}, **PLUGIN_ENV, **local}
    env["PATH"] = f"{BIN}{os.pathsep}{env.get('PATH', '')}"
    return env


class Procs:
    """Every process this test starts, each in its own session so that a kill takes its children
    (nanny + worker process) with it, the way a container dies."""

    def __init__(self, logdir: Path):
        self.logdir = logdir
        self.procs: list[tuple[subprocess.Popen, Path]] = []

    def start(self, name: str, cmd: list[str], env: dict) -> subprocess.Popen:
        log = self.logdir / f"{name}.log"
        with open(log, "wb") as fh:
            p = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=fh, stderr=subprocess.STDOUT, start_new_session=True)
        self.procs.append((p, log))
        return p

    def log_of(self, p: subprocess.Popen, tail: int | None = 3000) -> str:
        for q, log in self.procs:
            if q is p:
                text = log.read_text(errors="replace")
                return text if tail is None else text[-tail:]
        return ""

    def logs(self) -> str:
        return "\n".join(
            f"--- {log.name} (exit {p.poll()}) ---\n{log.read_text(errors='replace')[-2000:]}" for p, log in self.procs
        )

    def stop_all(self) -> None:
        # newest first, one at a time: the API's client disconnects before the scheduler goes (no
        # reconnect loop at shutdown), and workers leave before the scheduler they report to
        for p, _ in reversed(self.procs):
            for sig, wait in ((signal.SIGTERM, 10), (signal.SIGKILL, 10)):
                try:
                    os.killpg(p.pid, sig)  # the whole group: nanny, worker, resource tracker
                except ProcessLookupError:
                    pass
                try:
                    p.wait(wait)
                    break
                except subprocess.TimeoutExpired:
                    continue
            try:
                os.killpg(p.pid, signal.SIGKILL)  # a child that outlived its leader
            except ProcessLookupError:
                pass


def _wait_http(procs: Procs, p: subprocess.Popen, url: str, ok, what: str, timeout: float = 90.0):
    t0 = time.time()
    while True:
        try:
            r = httpx.get(url, timeout=2)
            if r.status_code == 200 and ok(r):
                return
        except httpx.HTTPError:
            pass
        if p.poll() is not None or time.time() - t0 > timeout:
            raise RuntimeError(
                f"{what} not healthy at {url} after {time.time() - t0:.0f} s "
                f"(exit code {p.poll()}); its output:\n{procs.log_of(p)}"
            )
        time.sleep(0.1)


def _port_of(procs: Procs, p: subprocess.Popen, prefix: str, what: str, timeout: float = 90.0) -> int:
    """The port a process bound to port 0 names in its output after ``prefix``."""
    t0 = time.time()
    while (port := listening_port(procs.log_of(p, tail=None), prefix)) is None:
        if p.poll() is not None or time.time() - t0 > timeout:
            raise RuntimeError(
                f"{what} named no port after {time.time() - t0:.0f} s (exit code {p.poll()}); "
                f"its output:\n{procs.log_of(p)}"
            )
        time.sleep(0.1)
    return port


@contextmanager
def deployed_cluster(tmp: Path):
    """Scheduler, workers and API as the compose file starts them, each on ports the system picks (port 0) and
    names in its output: a port looked up free here and handed over could be taken by another process (each
    worker binds random ports of its own) before its owner bound it."""
    svcs = _compose()["services"]
    procs = Procs(tmp)
    data = tmp / "data"  # stands in for the shared volume
    data.mkdir(parents=True)
    try:
        sch = svcs["scheduler"]
        p_sch = procs.start(
            "scheduler",
            _local(sch["command"], {"--host": "127.0.0.1", "--port": "0", "--dashboard-address": "127.0.0.1:0"}),
            _env(sch["environment"]),
        )
        sched_port = _port_of(procs, p_sch, r"Scheduler at:\s+tcp://127\.0\.0\.1:", "scheduler")
        address = f"tcp://127.0.0.1:{sched_port}"
        sched_dash = _port_of(procs, p_sch, r"dashboard at:\s+http://127\.0\.0\.1:", "scheduler's dashboard")
        # compose starts workers and API only once the scheduler's healthcheck passes: same probe
        _wait_http(procs, p_sch, f"http://127.0.0.1:{sched_dash}/health", lambda r: r.text == "ok", "scheduler")

        wrk = svcs["worker"]
        n_workers = int(wrk.get("deploy", {}).get("replicas", 2))
        assert n_workers >= 2, "the fault test needs a worker to survive the kill"
        compose_addr = next(a for a in wrk["command"] if a.startswith("tcp://"))
        workers = [
            procs.start(
                f"worker{i}",
                _local(wrk["command"], {"--dashboard-address": "127.0.0.1:0"}, {compose_addr: address}),
                _env(wrk["environment"]),
            )
            for i in range(n_workers)
        ]

        api = svcs["api"]
        api_env = _env(
            api["environment"],
            VFINFER_SCHEDULER=address,
            VFINFER_DATA_DIR=str(data),
            VFINFER_TOKENS=",".join(f"{u}:{t}" for u, t in TOKENS.items()),
            VFINFER_ALLOW_TOY="1",
        )  # the test double; never set in compose
        p_api = procs.start("api", _local(api["command"], {"--host": "127.0.0.1", "--port": "0"}), api_env)
        api_port = _port_of(procs, p_api, r"listening on http://127\.0\.0\.1:", "api")
        url = f"http://127.0.0.1:{api_port}"
        _wait_http(
            procs,
            p_api,
            f"{url}/health",
            lambda r: r.json()["status"] == "ok" and r.json()["dask_workers"] == n_workers,
            "api",
            timeout=120,
        )
        yield {"url": url, "address": address, "data": data, "workers": workers, "procs": procs}
    finally:
        procs.stop_all()


def _product_bytes(http: httpx.Client, stores_dir: Path, job_id: str, user: str) -> dict[str, bytes | dict]:
    """What a job published, as bytes: the summary (minus its id), the CSV the API serves, and every
    array of the store's posterior group and simulated batch (written chunk by chunk by workers)."""
    post = http.get(f"/jobs/{job_id}/posterior", headers=auth(user))
    post.raise_for_status()
    summary = post.json()
    assert summary.pop("id") == job_id
    csv = http.get(f"/jobs/{job_id}/samples", headers=auth(user))
    csv.raise_for_status()
    out: dict[str, bytes | dict] = {"summary": summary, "samples.csv": csv.content}
    store = stores_dir / f"{job_id}.zarr"
    out.update({f"posterior/{k}": v.tobytes() for k, v in st.read_posterior_arrays(store).items()})
    batch = zarr.open_group(str(store), mode="r", path="batches/0")
    for name, arr in batch.arrays():
        out[f"batches/0/{name}"] = np.asarray(arr[...]).tobytes()
    return out


def _assert_same(a: dict, b: dict, what: str) -> None:
    assert a.keys() == b.keys(), what
    for k in a:
        assert a[k] == b[k], f"{what}: {k} differs"


def _submit(http, spec, user="alice") -> str:
    r = http.post("/jobs", json=spec, headers=auth(user))
    assert r.status_code == 202, r.text
    return r.json()["id"]


# Separate scheduler, worker and API processes start and stop here: `make test-all` runs it.
@pytest.mark.slow
@pytest.mark.timeout(300)
@pytest.mark.skipif(not DASK.exists(), reason=f"no `dask` command line in {BIN} (dask[distributed] not installed here)")
def test_external_scheduler_and_worker_processes_match_local_cluster_and_survive_a_worker_kill(tmp_path, service):
    from distributed import Client

    t_start = time.time()
    with (
        deployed_cluster(tmp_path / "deployed") as dep,
        httpx.Client(base_url=dep["url"], timeout=60) as http,
        Client(dep["address"], set_as_default=False, timeout=30) as observer,
    ):
        procs: Procs = dep["procs"]
        stores = dep["data"] / "stores"
        try:
            # the same job on the in-process LocalCluster (reference) and on the process cluster
            ref = _submit(service.http, SPEC)
            job = _submit(http, SPEC)
            assert wait_done(service.http, ref, "alice", timeout=120)["state"] == "done"
            st_job = wait_done(http, job, "alice", timeout=120)
            assert st_job["state"] == "done", st_job
            assert st_job["progress"]["simulations_done"] == 480
            expected = _product_bytes(service.http, service.settings.stores_dir, ref, "alice")
            _assert_same(expected, _product_bytes(http, stores, job, "alice"), "external cluster vs LocalCluster")

            # again, and SIGKILL the process group of a worker that is running one of its chunks:
            # nanny and worker process die together, as when a worker container is killed
            job2 = _submit(http, SPEC)
            t0 = time.time()
            killed = None
            while killed is None:
                now = http.get(f"/jobs/{job2}", headers=auth("alice")).json()
                assert now["state"] in ("queued", "running"), f"job ended before a worker could be killed: {now}"
                assert time.time() - t0 < 60, "job never had a chunk running on a worker"
                if now["progress"]["simulations_done"] >= 96:  # chunks written: mid-job
                    busy = [
                        w for w, keys in observer.processing().items() if any(f"vfchunk-{job2}" in str(k) for k in keys)
                    ]
                    if busy:
                        pid = observer.run(os.getpid, workers=[busy[0]])[busy[0]]
                        group = os.getpgid(pid)
                        victim = {p.pid: p for p in dep["workers"]}.get(group)
                        assert victim is not None, f"busy worker {busy[0]} is not one this test started"
                        os.killpg(group, signal.SIGKILL)
                        victim.wait(30)
                        killed = busy[0]
                time.sleep(0.02)
            st2 = wait_done(http, job2, "alice", timeout=120)
            assert st2["state"] == "done", st2
            assert st2["progress"]["simulations_done"] == 480
            # one run of all 20 chunks: the lost chunk was retried by the scheduler, not resumed by the API
            assert [(r["chunks_computed"], r["chunks_skipped"]) for r in st2["stats"]["runs"]] == [(20, 0)]
            workers_left = observer.scheduler_info(n_workers=-1)["workers"]
            assert killed not in workers_left and len(workers_left) == len(dep["workers"]) - 1
            _assert_same(expected, _product_bytes(http, stores, job2, "alice"), "after a worker was killed")
        except BaseException:
            print(procs.logs())  # shown by pytest on failure only
            raise
    print(f"\nprocess cluster test: {time.time() - t_start:.1f} s")
