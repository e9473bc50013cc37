"""Zarr v3 layout of one job.

::

    <job_id>.zarr/                  attrs: jobspec (JSON), job_id, layout, chunk_size, status
      batches/<b>/                  one batch of simulations: IS has one (b=0); SMC one per ask()
        attrs: n, n_chunks, chunk_size
        thetas       (n, d)          float64   estimated parameters, paper units
        loglik       (n,)            float64   -inf for failed simulations
        ok           (n,)            bool
        gaw          (n, n_compare)  float32   aligned simulated GAW (NaN rows for failures)
        mean_flow    (n,)            float64   m^3/s      (flow summary)
        mean_contact (n,)            float64   Pa         (contact summaries)
        max_contact  (n,)            float64   Pa         (nodal peaks: time-step and mesh dependent)
        contact_impulse (n,)         float64   N s/m      (per cycle and unit fold length)
        contact_pressure_in_contact (n,) float64 Pa       (mean over the contact patch while in contact)
        done         (n_chunks,)     bool      chunk c wrote rows [c*cs, (c+1)*cs)
      posterior/                    attrs: summary (JSON-able dict)
        samples (N, d), log_weights (N,), resampled (M,)
      products/                     uint8 blobs: figures (PNG), samples CSV + its JSON metadata, NetCDF

A diagnosis job's store holds less (:func:`create_diagnosis_store`)::

    <job_id>.zarr/                  attrs: kind="diagnosis", diagnosis (its spec, JSON), job_id, layout
      products/                     diagnosis_png (the figure), then diagnosis_json (the report: its presence
                                    means done)
      resume/                       finished simulations while it runs (vfcore.inference.memo.CachedMap;
                                    not Zarr, deleted once the report is written)

Every array of a batch is chunked along its first axis with the batch's ``chunk_size`` (the job's, or an
SMC generation's equal share per worker thread, fixed when the batch is created) so each worker task
owns whole Zarr chunks: concurrent tasks never write the same object, and a recomputed task
overwrites its region with identical bytes.  ``done`` has one element per Zarr chunk.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import zarr

from vfcore.inference.evaluation import Evaluation

LAYOUT_VERSION = 1
# zarr 3 raises its own error for a missing node; an older zarr, KeyError
_NODE_NOT_FOUND = zarr.errors.NodeNotFoundError if hasattr(zarr, "errors") else KeyError
EVAL_ARRAYS = (
    "loglik",
    "ok",
    "gaw",
    "mean_flow",
    "mean_contact",
    "max_contact",
    "contact_impulse",
    "contact_pressure_in_contact",
)
SUMMARY_ARRAYS = ("mean_flow", "mean_contact", "max_contact", "contact_impulse", "contact_pressure_in_contact")
PRODUCT_NAMES = (
    "gaw_fit",
    "corner",
    "contact_pressure",
    "samples_csv",
    "samples_meta",
    "posterior_nc",
    "diagnosis_json",
    "diagnosis_png",
)
#: The folder of a diagnosis store that keeps its finished simulations while it runs.
RESUME_DIR = "resume"


def create_job_store(path: Path, job_id: str, spec_json: str, chunk_size: int, n_compare: int, ndim: int):
    """Create (or reopen, when it already exists) the store of a job."""
    path = Path(path)
    if (path / "zarr.json").exists():
        return zarr.open_group(str(path), mode="r+")
    root = zarr.open_group(str(path), mode="w")
    root.attrs.update(
        {
            "layout": LAYOUT_VERSION,
            "job_id": job_id,
            "jobspec": json.loads(spec_json),
            "chunk_size": int(chunk_size),
            "n_compare": int(n_compare),
            "ndim": int(ndim),
        }
    )
    root.create_group("batches")
    return root


def create_diagnosis_store(path: Path, job_id: str, spec_json: str):
    """Create (or reopen) the store of a diagnosis job."""
    path = Path(path)
    if (path / "zarr.json").exists():
        return zarr.open_group(str(path), mode="r+")
    root = zarr.open_group(str(path), mode="w")
    root.attrs.update(
        {"layout": LAYOUT_VERSION, "kind": "diagnosis", "job_id": job_id, "diagnosis": json.loads(spec_json)}
    )
    return root


def open_store(path: Path, mode: str = "r+"):
    return zarr.open_group(str(path), mode=mode)


def batch_path(b: int) -> str:
    return f"batches/{int(b)}"


def ensure_batch(root, b: int, thetas: np.ndarray, chunk_size: int | None = None):
    """Pre-allocate batch ``b`` for ``thetas`` (idempotent: an existing batch must hold the same thetas, and
    keeps the chunking it was created with). ``chunk_size``: this batch's rows per chunk, else the job's."""
    cs = int(chunk_size or root.attrs["chunk_size"])
    n_cmp = int(root.attrs["n_compare"])
    name = batch_path(b)
    n, d = thetas.shape
    try:
        g = root[name]
        old = g["thetas"][...]
        if old.shape != thetas.shape or not np.array_equal(old, thetas):
            raise RuntimeError(f"store batch {b} holds different parameters than the replayed sampler asks for")
        return g
    except KeyError:
        pass
    n_chunks = max(1, -(-n // cs))
    g = root.create_group(name)
    g.attrs.update({"n": n, "n_chunks": n_chunks, "chunk_size": cs})
    c = max(1, min(cs, n))
    g.create_array("thetas", shape=(n, d), chunks=(c, d), dtype="float64")
    g.create_array("loglik", shape=(n,), chunks=(c,), dtype="float64", fill_value=np.nan)
    g.create_array("ok", shape=(n,), chunks=(c,), dtype="bool", fill_value=False)
    g.create_array("gaw", shape=(n, n_cmp), chunks=(c, n_cmp), dtype="float32", fill_value=np.nan)
    for s in SUMMARY_ARRAYS:
        g.create_array(s, shape=(n,), chunks=(c,), dtype="float64", fill_value=np.nan)
    g.create_array("done", shape=(n_chunks,), chunks=(1,), dtype="bool", fill_value=False)
    if n:
        g["thetas"][...] = thetas
    return g


def write_chunk(store_path: str, b: int, c: int, lo: int, ev: Evaluation) -> None:
    """Write one chunk's evaluation into its own region, then mark it done."""
    g = zarr.open_group(str(store_path), mode="r+", path=batch_path(b))
    hi = lo + len(ev)
    for name in EVAL_ARRAYS:
        a = getattr(ev, name)
        if a is None or name not in g:
            continue
        g[name][lo:hi] = a
    g["done"][c] = True


def done_mask(g) -> np.ndarray:
    return np.asarray(g["done"][...], dtype=bool)


def read_evaluation(g, lo: int = 0, hi: int | None = None) -> Evaluation:
    hi = int(g.attrs["n"]) if hi is None else hi
    # a store written before an array existed lacks it: read as absent
    kw = {name: g[name][lo:hi] for name in EVAL_ARRAYS if name in g}
    kw["ok"] = np.asarray(kw["ok"], dtype=bool)
    return Evaluation(**kw)


def write_blob(root, name: str, data: bytes) -> None:
    if name not in PRODUCT_NAMES:
        raise ValueError(f"unknown product {name!r}")
    prod = root.require_group("products")
    arr = np.frombuffer(data, dtype=np.uint8)
    a = prod.create_array(name, shape=arr.shape, chunks=(max(1, arr.size),), dtype="uint8", overwrite=True)
    a[...] = arr


def read_blob(path: Path, name: str) -> bytes | None:
    if name not in PRODUCT_NAMES:
        return None
    try:
        a = zarr.open_array(str(path), mode="r", path=f"products/{name}")
    except (KeyError, FileNotFoundError, _NODE_NOT_FOUND):
        return None
    return bytes(np.asarray(a[...], dtype=np.uint8))


def read_summary(path: Path) -> dict | None:
    try:
        g = zarr.open_group(str(path), mode="r", path="posterior")
    except Exception:  # noqa: BLE001 - absent group -> no posterior yet
        return None
    s = g.attrs.get("summary")
    return dict(s) if s is not None else None


def read_posterior_arrays(path: Path) -> dict[str, np.ndarray]:
    g = zarr.open_group(str(path), mode="r", path="posterior")
    return {k: g[k][...] for k in ("samples", "log_weights", "resampled")}
