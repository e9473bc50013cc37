"""Durable job table (SQLite, beside the Zarr stores).

The table is the service's source of truth for ownership and state; the store of a job is the
source of truth for its numbers.  One connection guarded by a lock (WAL journal), so the runner
threads and request handlers can share it.

Every kind of job lives here: an inference (``kind="inference"``, its spec a ``JobSpec``) and a
diagnosis of a finished inference (``kind="diagnosis"``, its spec a ``DiagnosisSpec``, ``parent`` the
job diagnosed). ``sampler`` and ``model`` are written at submission so that a status read never
parses a spec again.
"""

from __future__ import annotations

import json
import secrets
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
#: Columns added after the first release, with their definitions: a table made before them gains them
#: when it is opened (:meth:`JobDB._migrate`).
_ADDED = (("kind", "TEXT NOT NULL DEFAULT 'inference'"), ("parent", "TEXT"), ("sampler", "TEXT"), ("model", "TEXT"))

_COLS = (
    "id",
    "owner",
    "state",
    "spec",
    "created",
    "started",
    "finished",
    "n_done",
    "n_total",
    "ess",
    "error",
    "stats",
    "attempts",
    "kind",
    "parent",
    "sampler",
    "model",
)


def spec_labels(spec_json: str) -> tuple[str, str]:
    """(sampler kind, model) of an inference spec, read from its JSON without validating it."""
    try:
        spec = json.loads(spec_json)
    except ValueError:
        return "?", "?"
    return str((spec.get("sampler") or {}).get("kind", "?")), str(spec.get("model", "fe"))


def new_job_id() -> str:
    """128 random bits as 32 hex digits: unguessable, the only thing a store path is built from,
    and never starting with "-" (a URL-safe token does 1 time in 64, and the CLI then reads the id
    as an option: ``vfinfer status -n...`` failed with "No such option: -n")."""
    return secrets.token_hex(16)


class JobDB:
    def __init__(self, path: Path):
        path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        self._con = sqlite3.connect(str(path), check_same_thread=False, isolation_level=None)
        with self._lock:
            self._con.execute("PRAGMA journal_mode=WAL")
            self._con.execute("PRAGMA synchronous=NORMAL")
            self._con.executescript(_SCHEMA)
            self._migrate()

    def _migrate(self) -> None:
        """Bring a table made by an earlier release up to this schema: add the missing columns, fill
        ``sampler``/``model`` from the stored specs, index diagnoses by the job they diagnose."""
        have = {r[1] for r in self._con.execute("PRAGMA table_info(jobs)")}
        for name, definition in _ADDED:
            if name not in have:
                self._con.execute(f"ALTER TABLE jobs ADD COLUMN {name} {definition}")
        rows = self._con.execute("SELECT id, spec FROM jobs WHERE sampler IS NULL AND kind='inference'").fetchall()
        for job_id, spec in rows:
            self._con.execute("UPDATE jobs SET sampler=?, model=? WHERE id=?", (*spec_labels(spec), job_id))
        self._con.execute("CREATE INDEX IF NOT EXISTS jobs_parent ON jobs(parent, created)")

    def close(self) -> None:
        with self._lock:
            self._con.close()

    def _row(self, r) -> dict | None:
        if r is None:
            return None
        d = dict(zip(_COLS, r))
        d["stats"] = json.loads(d["stats"]) if d["stats"] else {}
        return d

    def insert(
        self,
        job_id: str,
        owner: str,
        spec_json: str,
        n_total: int,
        *,
        kind: str = "inference",
        parent: str | None = None,
        sampler: str | None = None,
        model: str | None = None,
    ) -> None:
        if kind == "inference" and (sampler is None or model is None):
            sampler, model = spec_labels(spec_json)
        with self._lock:
            self._con.execute(
                "INSERT INTO jobs (id, owner, state, spec, created, n_total, kind, parent, sampler, model)"
                " VALUES (?,?,?,?,?,?,?,?,?,?)",
                (job_id, owner, "queued", spec_json, time.time(), n_total, kind, parent, sampler, model),
            )

    def get(self, job_id: str, owner: str | None = None, kind: str | None = None) -> dict | None:
        q = f"SELECT {','.join(_COLS)} FROM jobs WHERE id=?"
        args: tuple = (job_id,)
        if owner is not None:
            q += " AND owner=?"
            args += (owner,)
        if kind is not None:
            q += " AND kind=?"
            args += (kind,)
        with self._lock:
            return self._row(self._con.execute(q, args).fetchone())

    def list(
        self, owner: str | None = None, states: tuple[str, ...] | None = None, kind: str | None = "inference"
    ) -> list[dict]:
        """Jobs in submission order; ``kind=None``: every kind (the default lists inferences, what the job
        listings show)."""
        q = f"SELECT {','.join(_COLS)} FROM jobs WHERE 1=1"
        args: list = []
        if owner is not None:
            q += " AND owner=?"
            args.append(owner)
        if states:
            q += f" AND state IN ({','.join('?' * len(states))})"
            args += list(states)
        if kind is not None:
            q += " AND kind=?"
            args.append(kind)
        q += " ORDER BY created"
        with self._lock:
            return [self._row(r) for r in self._con.execute(q, args).fetchall()]

    def children(self, parent: str, kind: str = "diagnosis") -> list[dict]:
        """The jobs of ``kind`` made of job ``parent``, newest first."""
        with self._lock:
            return [
                self._row(r)
                for r in self._con.execute(
                    f"SELECT {','.join(_COLS)} FROM jobs WHERE parent=? AND kind=? ORDER BY created DESC, rowid DESC",
                    (parent, kind),
                ).fetchall()
            ]

    def delete(self, job_id: str) -> bool:
        with self._lock:
            return self._con.execute("DELETE FROM jobs WHERE id=?", (job_id,)).rowcount > 0

    def count_active(self, owner: str, kind: str = "inference") -> int:
        with self._lock:
            return int(
                self._con.execute(
                    "SELECT COUNT(*) FROM jobs WHERE owner=? AND kind=? AND state IN ('queued','running')",
                    (owner, kind),
                ).fetchone()[0]
            )

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
