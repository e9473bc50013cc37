"""Helpers shared by the service tests (imported by name: the test folders are not packages)."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import uvicorn

_DOUBLES = str(Path(__file__).resolve().parents[1] / "doubles")
if _DOUBLES not in sys.path:  # benchmarks/bench_service.py imports this module by name, outside pytest
    sys.path.insert(0, _DOUBLES)
from toy_model import PLUGIN_ENV, toy_observation  # noqa: E402

TOKENS = {"alice": "alice-token-0123456789", "bob": "bob-token-0123456789", "carol": "carol-token-0123456789"}


def auth(user: str) -> dict:
    return {"Authorization": f"Bearer {TOKENS[user]}"}


def toy_spec(n: int = 400, seed: int = 1, delay: float = 0.0, sampler: dict | None = None, **kw) -> dict:
    """A valid toy-model job (the analytic test double; see tests/doubles/toy_model.py)."""
    spec = {
        "model": "toy",
        "model_options": {"delay_s": delay},
        "gaw": {"areas": toy_observation(noise=0.5, seed=7), "fps": 4000.0, "units": "mm2"},
        "priors": {"E_cover": [450.0, 850.0], "p_sub": [700.0, 1300.0]},
        "fixed": {"E_body": 12.15, "E_lig": 1.808, "rho": 1051.0, "eta": 3.079, "x0": 8.4},
        "sampler": sampler or {"kind": "is", "n_samples": n},
        "duration": 0.35,
        "discard": 0.2,
        "sigma_e": 10.0,
        "seed": seed,
    }
    spec.update(kw)
    return spec


ROOT = Path(__file__).resolve().parents[2]


def start_service(
    data_dir: Path, script: list[str] | None = None, env: dict | None = None
) -> tuple[subprocess.Popen, int]:
    """``vfinfer serve`` (or ``script``, a command line run with this Python that serves the same way) in its own
    process group, with a LocalCluster of 2 workers and the test tokens, on ``data_dir``; returns the process and
    its port once both workers answer. The service is given port 0 and binds before it starts anything else: the
    port is the system's pick, named on its ``listening on`` line, and no other process can take it in between
    (a port looked up free here and handed over would be free only until something else bound it)."""
    env = {
        **os.environ,
        "VFINFER_DATA_DIR": str(data_dir),
        "VFINFER_ALLOW_TOY": "1",
        "VFINFER_N_WORKERS": "2",
        "VFINFER_TOKENS": ",".join(f"{u}:{t}" for u, t in TOKENS.items()),
        "OMP_NUM_THREADS": "1",
        **PLUGIN_ENV,
        **(env or {}),
    }
    import httpx

    log = data_dir.parent / f"serve_{time.time_ns()}.log"  # kept for the error message
    argv = [sys.executable, *(script or ["-m", "service.cli"]), "serve", "--port", "0"]
    with open(log, "wb") as fh:
        p = subprocess.Popen(argv, cwd=ROOT, env=env, stdout=fh, stderr=subprocess.STDOUT, start_new_session=True)
    t0 = time.time()
    port = None
    while True:
        if port is None:
            port = listening_port(log.read_text(errors="replace"), r"listening on http://127\.0\.0\.1:")
        if port is not None:
            try:
                if httpx.get(f"http://127.0.0.1:{port}/health", timeout=1).json()["dask_workers"] == 2:
                    return p, port
            except (httpx.HTTPError, KeyError, ValueError):
                pass
        if time.time() - t0 > 180 or p.poll() is not None:
            rc = p.poll()
            kill_service(p)
            raise RuntimeError(
                f"service did not start (port {port}) within {time.time() - t0:.0f} s "
                f"(exit code {rc}); its output:\n{log.read_text(errors='replace')[-3000:]}"
            )
        time.sleep(0.2)


def listening_port(log: str, prefix: str) -> int | None:
    """The port in the first ``<prefix><port>`` of a process's output (``prefix`` a regular expression), or None
    before it is written."""
    import re

    m = re.search(prefix + r"(\d+)", log)
    return int(m.group(1)) if m else None


def kill_service(p: subprocess.Popen) -> None:
    """SIGKILL the service and every process it started (its LocalCluster): a host crash."""
    try:
        os.killpg(p.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    p.wait(30)


class ServerThread:
    """``app`` served by uvicorn in a thread of this process, on a socket bound here to a port the system picks
    (bound before the app's lifespan starts anything, as ``vfinfer serve`` does)."""

    def __init__(self, app):
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(2048)
        self.port = self.sock.getsockname()[1]
        self.url = f"http://127.0.0.1:{self.port}"
        self.server = uvicorn.Server(
            uvicorn.Config(app, host="127.0.0.1", port=self.port, log_level="warning", lifespan="on")
        )
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self.sock]}, daemon=True)

    def __enter__(self):
        self.thread.start()
        t0 = time.time()
        while not self.server.started:
            if time.time() - t0 > 60 or not self.thread.is_alive():
                raise RuntimeError("uvicorn did not start")
            time.sleep(0.02)
        return self

    def __exit__(self, *exc):
        self.server.should_exit = True
        self.thread.join(30)
        self.sock.close()


def wait_done(http, job_id: str, user: str, timeout: float = 120.0, states=("done", "failed", "cancelled")) -> dict:
    t0 = time.time()
    while True:
        r = http.get(f"/jobs/{job_id}", headers=auth(user))
        r.raise_for_status()
        st = r.json()
        if st["state"] in states:
            return st
        if time.time() - t0 > timeout:
            raise TimeoutError(f"job {job_id} still {st['state']}: {st}")
        time.sleep(0.1)


class HalfSquare:
    """A picklable batch function standing in for the forward model: -|x|^2 / 2 per row."""

    def __call__(self, rows):
        import numpy as np

        from vfcore.inference.problem import Evaluation

        return Evaluation.from_loglik(-0.5 * np.sum(np.asarray(rows) ** 2, axis=1))


def dying_diagnosis(seen: list, message: str, n_parts: int = 3):
    """A stand-in for vfcore.diagnose.pipeline.diagnose that records the ``map`` it is given,
    evaluates ``n_parts`` parts through it and then dies with RuntimeError(message)."""
    import numpy as np

    def diagnose(problem, *, map, **kw):
        seen.append(map)
        list(map(HalfSquare(), [np.full((2, 1), float(k)) for k in range(n_parts)]))
        raise RuntimeError(message)

    return diagnose


def done_fe_job(settings, owner: str = "alice", spec: dict | None = None) -> str:
    """A finished finite-element job put straight into the job table (its diagnosis is replaced
    by a stand-in in the tests that use it, so nothing of it is simulated; ``spec``: another job's)."""
    import json

    import numpy as np

    from service.db import JobDB
    from service.manager import new_job_id

    if spec is None:
        t = np.arange(800) / 4000.0
        areas = 8.0 * np.maximum(np.sin(2 * np.pi * 120.0 * t), 0.0) + 0.5
        spec = {
            "model": "fe",
            "gaw": {"areas": [float(a) for a in areas], "fps": 4000.0, "units": "mm2"},
            "fixed": {"E_body": 12.15, "E_lig": 1.808, "rho": 1051.0, "eta": 3.079, "x0": 8.4, "p_sub": 1000.0},
            "sampler": {"kind": "is", "n_samples": 16},
            "sigma_e": 1.0,
            "seed": 1,
            "mesh": "coarse",
            "dt": 1e-4,
            "duration": 0.35,
            "discard": 0.15,
        }
    settings.stores_dir.mkdir(parents=True, exist_ok=True)
    db = JobDB(settings.db_path)
    jid = new_job_id()
    db.insert(jid, owner, json.dumps(spec), 16)
    db.update(jid, state="done")
    db.close()
    return jid


def leaky_fe_spec(fps: float = 4000.0) -> dict:
    """A tiny FE job on a Table 3 simulation with a hidden 1.5 mm^2 leak and N(0, 0.3^2) noise: what the
    diagnosis tests diagnose for real (coarse mesh, dt 1e-4 s, 0.35 s simulated)."""
    import numpy as np

    from vfcore import TABLE3, SimConfig, simulate

    cfg = dict(mesh="coarse", dt=1e-4, duration=0.35, discard=0.15)
    r = simulate(TABLE3, SimConfig(fps=fps, **cfg))
    assert r.ok, r.message
    y = np.clip(r.gaw + 1.5 + np.random.default_rng(3).normal(0.0, 0.3, r.gaw.size), 0.0, None)
    fixed = {k: v for k, v in TABLE3.as_dict().items() if k != "E_cover"}
    return {
        "model": "fe",
        "gaw": {"areas": [float(a) for a in y], "fps": fps, "units": "mm2"},
        "fixed": fixed,
        "sampler": {"kind": "is", "n_samples": 16},
        "sigma_e": 1.0,
        "seed": 1,
        "chunk_size": 8,
        **cfg,
    }


def store_diagnosis(
    settings,
    job_id: str,
    state: str = "done",
    report: dict | None = None,
    png: bytes | None = None,
    error: str | None = None,
) -> str:
    """A diagnosis of the finished job ``job_id`` put straight into the job table and its store, as the service
    leaves one in ``state`` (``report``: as ``DiagnoseReport.to_dict()`` after ``jsonable``, its ``request`` the
    settings); returns the diagnosis's id."""
    import time

    from service.api_models import DiagnoseRequest, DiagnosisSpec
    from service.db import JobDB, new_job_id
    from service.diagnosis import write_report

    db = JobDB(settings.db_path)
    try:
        owner = db.get(job_id)["owner"]
        report = dict(report) if report is not None else None
        spec = DiagnosisSpec(job=job_id, request=DiagnoseRequest(**((report or {}).pop("request", None) or {})))
        diag = new_job_id()
        db.insert(diag, owner, spec.to_json(), 0, kind="diagnosis", parent=job_id, sampler="smc", model="fe")
        fields = {"state": state, "started": time.time(), "error": error}
        if state == "done":
            clock = write_report(settings.stores_dir / f"{diag}.zarr", diag, spec.to_json(), report, png)
            fields.update(finished=time.time(), stats={"clock": clock})
        db.update(diag, **fields)
    finally:
        db.close()
    return diag


def show_running(manager, diag_id: str, event: dict):
    """Make the manager show a running diagnosis's progress ``event`` (what its runner thread would set): a
    context manager."""
    from contextlib import contextmanager

    from service.manager import Live
    from worker.run import JobControl, Progress

    @contextmanager
    def _cm():
        live = Live(
            progress=Progress(n_done=event.get("simulations", 0), phase=event["stage"]),
            control=JobControl(),
            started=0.0,
            event=event,
        )
        with manager._lock:
            manager._live[diag_id] = live
        try:
            yield live
        finally:
            with manager._lock:
                manager._live.pop(diag_id, None)

    return _cm()
