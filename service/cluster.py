"""The Dask client of the service: an external scheduler, or a LocalCluster (laptop, pytest)."""

from __future__ import annotations

from .settings import Settings


def make_client(settings: Settings):
    """Return (client, cluster_or_None). Blocking: call from a thread, not the event loop."""
    from distributed import Client, LocalCluster

    if settings.scheduler_address:
        return Client(settings.scheduler_address, set_as_default=False), None
    cluster = LocalCluster(
        n_workers=settings.n_workers,
        threads_per_worker=settings.threads_per_worker,
        processes=True,
        dashboard_address=None,
    )
    return Client(cluster, set_as_default=False), cluster


def close_client(client, cluster) -> None:
    try:
        client.close()
    finally:
        if cluster is not None:
            cluster.close()
