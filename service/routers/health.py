"""GET /health: liveness plus a view of the cluster (no authentication, no job data)."""
from __future__ import annotations

from fastapi import APIRouter

from ..deps import ManagerDep

router = APIRouter(tags=["health"])


@router.get("/health")
def health(manager: ManagerDep) -> dict:
    try:
        info = manager.client.scheduler_info(n_workers=-1) if manager.client is not None else {}
        n_workers = len(info.get("workers", {}))
        ok = manager.client is not None and manager.client.status == "running"
    except Exception:  # noqa: BLE001 - health reports, never raises
        n_workers, ok = 0, False
    return {"status": "ok" if ok else "degraded", "dask_workers": n_workers, "queued": manager.queue_length()}
