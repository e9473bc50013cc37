"""Fixtures: one in-process LocalCluster (2 worker processes x 1 thread) and a real uvicorn
server on 127.0.0.1 running the app against it."""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")

import httpx  # noqa: E402
import pytest  # noqa: E402
from svc_helpers import TOKENS, ServerThread  # noqa: E402

from service.main import create_app  # noqa: E402
from service.settings import Settings  # noqa: E402


@pytest.fixture(scope="session")
def dask_client():
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    client = Client(cluster)
    yield client
    client.close()
    cluster.close()


@pytest.fixture
def settings(tmp_path) -> Settings:
    return Settings(
        data_dir=tmp_path / "data", users=TOKENS, allow_toy_model=True, max_running_jobs=4, max_body_bytes=2_000_000
    )


@pytest.fixture
def service(settings, dask_client):
    app = create_app(settings, client=dask_client)
    with ServerThread(app) as srv:
        srv.settings = settings
        srv.client = dask_client
        with httpx.Client(base_url=srv.url, timeout=60) as http:
            srv.http = http
            yield srv
