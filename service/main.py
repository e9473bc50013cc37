"""FastAPI application: settings, Dask client and job manager are created in the lifespan."""

from __future__ import annotations

import asyncio
from contextlib import asynccontextmanager

from fastapi import FastAPI
from fastapi_offline import FastAPIOffline

from . import errors
from .cluster import close_client, make_client
from .db import JobDB
from .limits import BodySizeLimit
from .manager import JobManager
from .routers import diagnose, gaw, health, jobs, pages
from .settings import Settings
from .signing import Signer


def create_app(settings: Settings | None = None, client=None) -> FastAPI:
    """``client``: an existing Dask client to use (tests); otherwise one is made from settings."""

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        s = settings or Settings.from_env()
        own = client is None
        cl, cluster = (await asyncio.to_thread(make_client, s)) if own else (client, None)
        db = JobDB(s.db_path)
        manager = JobManager(s, db, cl)
        app.state.settings, app.state.manager = s, manager
        app.state.signer = Signer.from_settings(s)  # keys the signed links of the HTML pages
        manager.start()  # interrupted jobs, inferences and diagnoses, go on
        try:
            yield
        finally:
            await asyncio.to_thread(manager.stop)
            db.close()
            if own:
                await asyncio.to_thread(close_client, cl, cluster)

    # /docs and /redoc load Swagger UI and ReDoc from the installed package, never from a CDN
    app = FastAPIOffline(
        title="vfinfer",
        version="0.1.0",
        lifespan=lifespan,
        description="Distributed Bayesian inference of vocal-fold properties from GAWs",
    )
    errors.install(app)
    app.include_router(pages.router)
    app.include_router(health.router)
    app.include_router(jobs.router)
    app.include_router(gaw.router)
    app.include_router(diagnose.router)
    app.add_middleware(BodySizeLimit, max_bytes=(settings or Settings.from_env()).max_body_bytes)
    return app
