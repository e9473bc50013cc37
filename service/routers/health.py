"""GET /health: liveness plus a view of the cluster (no authentication, no job data)."""

from __future__ import annotations

from fastapi import APIRouter, Response

from ..deps import ManagerDep

router = APIRouter(tags=["health"])


@router.get("/health", summary="Liveness and readiness: the job table and the Dask cluster (503 when degraded)")
def health(manager: ManagerDep, response: Response) -> dict:
    """200 with ``status: ok`` while the Dask client runs; 503 with ``status: degraded`` otherwise, so
    an orchestrator's healthcheck (docker-compose.yml) sees an API that has lost its scheduler."""
    try:
        info = manager.client.scheduler_info(n_workers=-1) if manager.client is not None else {}
        n_workers = len(info.get("workers", {}))
        ok = manager.client is not None and manager.client.status == "running"
    except Exception:  # noqa: BLE001 - health reports, never raises
        n_workers, ok = 0, False
    if not ok:
        response.status_code = 503
    return {"status": "ok" if ok else "degraded", "dask_workers": n_workers, "queued": manager.queue_length()}
