"""Overhead of the service: one job through HTTP -> queue -> chunks -> Zarr -> reducer, versus the
same simulations run directly with vfcore on the same Dask cluster.

    python benchmarks/bench_service.py --n 10000            # toy test double, 2 ms per simulation
    python benchmarks/bench_service.py --model fe --n 200   # the FE model (needs vfcore.simulate)

"direct" = ``vfcore.inference.importance_sample(..., map=<dask map>)`` on the same LocalCluster
(draw, evaluate in chunks, reduce in the driver; no store, no HTTP).  "service" = POST /jobs,
poll GET /jobs/{id} every 50 ms until done, GET the posterior.  Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "service"))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--model", choices=["toy", "fe"], default="toy")
    ap.add_argument("--delay", type=float, default=0.002, help="toy: seconds per simulation")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args()

    import tempfile

    import httpx
    import numpy as np
    from distributed import Client, LocalCluster

    from service.main import create_app
    from service.settings import Settings
    from svc_helpers import TOKENS, ServerThread, auth, toy_spec
    from vfcore.inference.importance import importance_sample
    from worker.jobspec import JobSpec
    from worker.run import chunk_size_for, evaluator_for

    if a.model == "toy":
        spec_d = toy_spec(n=a.n, seed=1, delay=a.delay)
    else:
        from vfcore.data import demo_spec_dict  # noqa: F401  (shipped demo observation)
        spec_d = demo_spec_dict(n=a.n)
    spec = JobSpec.model_validate(spec_d)
    problem = spec.to_problem()
    cs = chunk_size_for(spec)
    print(f"model={a.model} n={a.n} chunk_size={cs} workers={a.workers}x1 thread")
    with LocalCluster(n_workers=a.workers, threads_per_worker=1, processes=True, dashboard_address=None) as cl, \
            Client(cl) as client, tempfile.TemporaryDirectory() as tmp:
        def dask_map(fn, items):
            return client.gather(client.map(fn, list(items), pure=False))

        settings = Settings(data_dir=Path(tmp), users=TOKENS, allow_toy_model=True)
        app = create_app(settings, client=client)   # its lifespan warms the workers (imports, JIT)
        direct_t, svc_t = [], []
        with ServerThread(app) as srv, httpx.Client(base_url=srv.url, timeout=60) as http:
            for rep in range(a.repeat):
                t0 = time.perf_counter()
                post = importance_sample(evaluator_for(spec, problem), problem.prior, spec.n_simulations, spec.seed,
                                         map=dask_map, chunk_size=cs)
                direct_t.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                jid = http.post("/jobs", json=spec_d, headers=auth("alice")).json()["id"]
                while http.get(f"/jobs/{jid}", headers=auth("alice")).json()["state"] not in ("done", "failed"):
                    time.sleep(0.05)
                summ = http.get(f"/jobs/{jid}/posterior", headers=auth("alice")).json()
                svc_t.append(time.perf_counter() - t0)
                st = http.get(f"/jobs/{jid}", headers=auth("alice")).json()
                same = np.allclose([r["mean"] for r in summ["table"]], post.mean, rtol=0, atol=0)
                print(f"rep {rep}: direct {direct_t[-1]:.2f} s   service {svc_t[-1]:.2f} s "
                      f"(simulate {st['stats']['simulate_s']:.2f} s, reduce+figures {st['stats']['reduce_s']:.2f} s)"
                      f"   overhead {100 * (svc_t[-1] / direct_t[-1] - 1):+.1f} %   same posterior: {same}")
    d, s = min(direct_t), min(svc_t)
    print(f"best of {a.repeat}: direct {d:.2f} s, service {s:.2f} s -> overhead {100 * (s / d - 1):+.1f} % "
          f"({a.n} simulations, {a.n / s:.0f} sims/s through the service)")


if __name__ == "__main__":
    main()
