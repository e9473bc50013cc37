"""Helpers shared by the service tests (imported by name: tests/ has no packages)."""
from __future__ import annotations

import socket
import threading
import time

import uvicorn

from worker.toy import toy_observation

TOKENS = {"alice": "alice-token-0123456789", "bob": "bob-token-0123456789", "carol": "carol-token-0123456789"}


def auth(user: str) -> dict:
    return {"Authorization": f"Bearer {TOKENS[user]}"}


def toy_spec(n: int = 400, seed: int = 1, delay: float = 0.0, sampler: dict | None = None, **kw) -> dict:
    """A valid toy-model job (the analytic test double; see worker/toy.py)."""
    spec = {"model": "toy", "toy": {"delay_s": delay},
            "gaw": {"areas": toy_observation(noise=0.5, seed=7), "fps": 4000.0, "units": "mm2"},
            "priors": {"E_cover": [450.0, 850.0], "p_sub": [700.0, 1300.0]},
            "fixed": {"E_body": 12.15, "E_lig": 1.808, "rho": 1051.0, "eta": 3.079, "x0": 8.4},
            "sampler": sampler or {"kind": "is", "n_samples": n},
            "duration": 0.35, "discard": 0.2, "sigma_e": 10.0, "seed": seed}
    spec.update(kw)
    return spec


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ServerThread:
    def __init__(self, app):
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=self.port, log_level="warning",
                                                    lifespan="on"))
        self.thread = threading.Thread(target=self.server.run, daemon=True)

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


def done_fe_job(settings, owner: str = "alice") -> str:
    """A finished finite-element job put straight into the job table (its diagnosis is replaced
    by a stand-in in the tests that use it, so nothing of it is simulated)."""
    import json

    import numpy as np

    from service.db import JobDB
    from service.manager import new_job_id
    t = np.arange(800) / 4000.0
    areas = 8.0 * np.maximum(np.sin(2 * np.pi * 120.0 * t), 0.0) + 0.5
    spec = {"model": "fe", "gaw": {"areas": [float(a) for a in areas], "fps": 4000.0, "units": "mm2"},
            "fixed": {"E_body": 12.15, "E_lig": 1.808, "rho": 1051.0, "eta": 3.079, "x0": 8.4, "p_sub": 1000.0},
            "sampler": {"kind": "is", "n_samples": 16}, "sigma_e": 1.0, "seed": 1, "mesh": "coarse",
            "dt": 1e-4, "duration": 0.35, "discard": 0.15}
    settings.stores_dir.mkdir(parents=True, exist_ok=True)
    db = JobDB(settings.db_path)
    jid = new_job_id()
    db.insert(jid, owner, json.dumps(spec), 16)
    db.update(jid, state="done")
    db.close()
    return jid
