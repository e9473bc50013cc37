"""Durable job table (SQLite, beside the Zarr stores).

The table is the service's source of truth for ownership and state; the Zarr store of a job is
the source of truth for its numbers.  One connection guarded by a lock (WAL journal), so the
runner threads and request handlers can share it.
"""
from __future__ import annotations

import json
import sqlite3
import threading
import time
from pathlib import Path

ACTIVE = ("queued", "running")
FINAL = ("done", "failed", "cancelled")

_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id        TEXT PRIMARY KEY,
    owner     TEXT NOT NULL,
    state     TEXT NOT NULL,
    spec      TEXT NOT NULL,
    created   REAL NOT NULL,
    started   REAL,
    finished  REAL,
    n_done    INTEGER NOT NULL DEFAULT 0,
    n_total   INTEGER NOT NULL DEFAULT 0,
    ess       REAL,
    error     TEXT,
    stats     TEXT,
    attempts  INTEGER NOT NULL DEFAULT 0
);
CREATE INDEX IF NOT EXISTS jobs_owner ON jobs(owner, created);
CREATE INDEX IF NOT EXISTS jobs_state ON jobs(state);
"""

_COLS = ("id", "owner", "state", "spec", "created", "started", "finished", "n_done", "n_total", "ess",
         "error", "stats", "attempts")


class JobDB:
    def __init__(self, path: Path):
        path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        self._con = sqlite3.connect(str(path), check_same_thread=False, isolation_level=None)
        with self._lock:
            self._con.execute("PRAGMA journal_mode=WAL")
            self._con.execute("PRAGMA synchronous=NORMAL")
            self._con.executescript(_SCHEMA)

    def close(self) -> None:
        with self._lock:
            self._con.close()

    def _row(self, r) -> dict | None:
        if r is None:
            return None
        d = dict(zip(_COLS, r))
        d["stats"] = json.loads(d["stats"]) if d["stats"] else {}
        return d

    def insert(self, job_id: str, owner: str, spec_json: str, n_total: int) -> None:
        with self._lock:
            self._con.execute("INSERT INTO jobs (id, owner, state, spec, created, n_total) VALUES (?,?,?,?,?,?)",
                              (job_id, owner, "queued", spec_json, time.time(), n_total))

    def get(self, job_id: str, owner: str | None = None) -> dict | None:
        q = f"SELECT {','.join(_COLS)} FROM jobs WHERE id=?"
        args: tuple = (job_id,)
        if owner is not None:
            q += " AND owner=?"
            args += (owner,)
        with self._lock:
            return self._row(self._con.execute(q, args).fetchone())

    def list(self, owner: str | None = None, states: tuple[str, ...] | None = None) -> list[dict]:
        q = f"SELECT {','.join(_COLS)} FROM jobs WHERE 1=1"
        args: list = []
        if owner is not None:
            q += " AND owner=?"
            args.append(owner)
        if states:
            q += f" AND state IN ({','.join('?' * len(states))})"
            args += list(states)
        q += " ORDER BY created"
        with self._lock:
            return [self._row(r) for r in self._con.execute(q, args).fetchall()]

    def count_active(self, owner: str) -> int:
        with self._lock:
            return int(self._con.execute("SELECT COUNT(*) FROM jobs WHERE owner=? AND state IN ('queued','running')",
                                         (owner,)).fetchone()[0])

    def update(self, job_id: str, *, only_if_state: tuple[str, ...] | None = None, **fields) -> bool:
        if "stats" in fields and not isinstance(fields["stats"], str):
            fields["stats"] = json.dumps(fields["stats"])
        sets = ", ".join(f"{k}=?" for k in fields)
        q = f"UPDATE jobs SET {sets} WHERE id=?"
        args = list(fields.values()) + [job_id]
        if only_if_state:
            q += f" AND state IN ({','.join('?' * len(only_if_state))})"
            args += list(only_if_state)
        with self._lock:
            return self._con.execute(q, args).rowcount > 0
