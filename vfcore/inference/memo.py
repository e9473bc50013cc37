"""A content-addressed store of batch evaluations, so that an interrupted ensemble resumes.

:class:`CachedMap` wraps any ``map`` (the builtin, a pool's ``imap``, a Dask adapter) for
:func:`vfcore.inference.importance.map_evaluate` and the diagnosis. Each call ``map(fn, parts)``
is keyed per part by the SHA-256 of the pickled batch function and the part's array (dtype, shape
and bytes). A part seen before is read back instead of simulated; the others go to the inner map
and are written, each atomically (temporary file, then rename), before the call returns.

Why this is safe. A forward simulation is a pure function of its batch function and its
parameters (the samplers pass their seeds explicitly, and no batch function here carries a random
state), and the key holds both in full, so a stored entry is exactly what the simulation would
return and a rerun is bit-identical to the uncached run (tests/vfcore/inference/test_memo.py). A batch
function whose pickle misses something that changes its output would break this; such a function
must not be cached. A function that cannot be pickled, or a call with a part that is not a
numeric array, is run uncached. Different bytes for the
same function (a lazily filled attribute, say) only cost a miss.

Entries live under ``root/<code fingerprint>/`` (:func:`code_fingerprint`: the ``vfcore`` sources
and the numerical libraries' versions), so a store left by other code is never read. The store is
for resuming one piece of work; it is not an archive. Delete it when that work is done. Entries
are pickles: keep a store where only its owner can write (as the service's data directory).

Cost of a resumed run. Each ``CachedMap`` also keeps an attempt record under ``attempts/`` (its
start and the seconds from its start to its latest stored part, rewritten as parts are stored,
at most every ``NOTE_EVERY_S`` seconds and always after a call's last part), so the run that finishes can report the wall time of the attempts before it
(:meth:`CachedMap.resume_summary`, :func:`account`). An attempt that was killed is counted up to
its last noted part (at most ``NOTE_EVERY_S`` before its last stored one): the part it was
computing when it died, whose result was lost, is not.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import pickle
import tempfile
import time
import uuid
from collections.abc import Callable
from pathlib import Path

import numpy as np


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """SHA-256 of every ``vfcore`` source file (path and bytes) and of the Python, NumPy, SciPy and
    Numba versions: what a simulation's result depends on besides its batch function's pickle
    (classes and functions pickle by name, not by code). Stores are kept per fingerprint, so
    after an upgrade nothing from the old code is read back."""
    import platform
    import sys

    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        h.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes() + b"\0")
    vers = [sys.version, platform.machine()]
    for mod in ("numpy", "scipy", "numba"):
        try:
            vers.append(f"{mod} {__import__(mod).__version__}")
        except ImportError:
            vers.append(f"{mod} -")
    h.update("\n".join(vers).encode())
    return h.hexdigest()


def _fn_digest(fn) -> bytes | None:
    for dumps in (pickle.dumps, _cloud_dumps):
        try:
            return hashlib.sha256(dumps(fn)).digest()
        except Exception:  # noqa: BLE001 - an unpicklable function is simply not cached
            continue
    return None


def _cloud_dumps(obj) -> bytes:
    import cloudpickle

    return cloudpickle.dumps(obj)


def _part_key(fdigest: bytes, part) -> str | None:
    """The part's key, or None for a part that is not a plain numeric array (an object array's
    bytes are addresses, not values)."""
    try:
        a = np.ascontiguousarray(part)
    except Exception:  # noqa: BLE001 - not array-like: not cached
        return None
    if a.dtype.kind not in "biufc":
        return None
    h = hashlib.sha256(fdigest)
    h.update(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.tobytes())
    return h.hexdigest()


#: the attempt record is rewritten at most this often while parts arrive (and always after the
#: last part of a call), so a killed attempt loses at most this much of its accounted time
NOTE_EVERY_S = 5.0


def _write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same folder, then rename: a
    reader sees the old file or the whole new one, never a half-written one."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


class CachedMap:
    """``map(fn, parts)`` through ``inner``, each part's result stored under ``root``.

    ``hits`` and ``misses`` count parts read back and parts simulated; ``uncached`` counts parts
    run without the store: their batch function could not be pickled, or a part of the call was
    not a numeric array. ``earlier_attempts`` and ``earlier_wall_s``: the attempts on this store
    before this one and their wall time, each up to its last stored part (module docstring).
    """

    def __init__(self, inner: Callable = map, root: str | os.PathLike = ".vfcache"):
        self.inner = inner
        self.root = Path(root) / code_fingerprint()[:16]
        self.root.mkdir(parents=True, exist_ok=True)
        self.hits = self.misses = self.uncached = 0
        self._stored = 0
        runs = self.root / "attempts"
        runs.mkdir(exist_ok=True)
        earlier = [self._read_attempt(f) for f in sorted(runs.glob("*.json"))]
        self.earlier_attempts = len(earlier)
        self.earlier_wall_s = float(sum(earlier))
        self._t0 = self._noted = time.perf_counter()
        self._started = time.time()
        self._attempt = (
            runs / f"{time.strftime('%Y%m%dT%H%M%S', time.gmtime(self._started))}-{uuid.uuid4().hex[:8]}.json"
        )
        self._note_attempt()

    @staticmethod
    def _read_attempt(path: Path) -> float:
        try:
            return max(0.0, float(json.loads(path.read_text())["elapsed_s"]))
        except (OSError, ValueError, KeyError, TypeError):  # unreadable record: counted as 0 s
            return 0.0

    def _note_attempt(self, force: bool = True) -> None:
        now = time.perf_counter()
        if not force and now - self._noted < NOTE_EVERY_S:
            return
        self._noted = now
        rec = {"started_unix": self._started, "elapsed_s": now - self._t0, "parts_stored": self._stored}
        _write_atomic(self._attempt, json.dumps(rec).encode())

    def resume_summary(self) -> dict:
        """What the store contributed to this run: parts read back, simulated and uncached, the
        attempts before this one and their wall time (each up to its last stored part)."""
        return {
            "parts_read": self.hits,
            "parts_simulated": self.misses,
            "parts_uncached": self.uncached,
            "earlier_attempts": self.earlier_attempts,
            "earlier_wall_s": self.earlier_wall_s,
        }

    def _path(self, key: str) -> Path:
        return self.root / key[:2] / f"{key}.pkl"

    def _store(self, key: str, value) -> None:
        path = self._path(key)
        path.parent.mkdir(exist_ok=True)
        _write_atomic(path, pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL))

    def _load(self, key: str):
        path = self._path(key)
        try:
            with open(path, "rb") as f:
                return True, pickle.load(f)
        except FileNotFoundError:
            return False, None
        except (pickle.UnpicklingError, EOFError, ValueError):  # unreadable: simulate again
            return False, None

    def __call__(self, fn, parts) -> list:
        parts = list(parts)
        digest = _fn_digest(fn)
        keys = None if digest is None else [_part_key(digest, p) for p in parts]
        if keys is None or None in keys:
            self.uncached += len(parts)
            return list(self.inner(fn, parts))
        out: list = [None] * len(parts)
        todo = []
        for i, key in enumerate(keys):
            found, value = self._load(key)
            if found:
                out[i] = value
            else:
                todo.append(i)
        self.hits += len(parts) - len(todo)
        self.misses += len(todo)
        if todo:
            n = 0
            for i, value in zip(todo, self.inner(fn, [parts[i] for i in todo])):  # stored as each arrives
                self._store(keys[i], value)
                out[i] = value
                n += 1
                self._stored += 1
                self._note_attempt(force=n == len(todo))
            if n != len(todo):
                raise RuntimeError(
                    f"the inner map returned {n} results for {len(todo)} parts; "
                    "CachedMap needs a map that gives one result per part"
                )
        return out


def account(report: dict, store: CachedMap | None) -> dict:
    """Add the resume store's summary to a diagnosis report dict (``report["resume_store"]``) and
    count the earlier attempts' wall time into ``report["wall_s"]`` (this attempt's alone is kept
    as ``resume_store["this_attempt_wall_s"]``). A run without a store is returned unchanged."""
    if store is None:
        return report
    s = store.resume_summary()
    s["this_attempt_wall_s"] = float(report.get("wall_s", 0.0))
    report["resume_store"] = s
    report["wall_s"] = s["this_attempt_wall_s"] + s["earlier_wall_s"]
    return report
