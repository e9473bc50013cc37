"""Service settings: a plain pydantic model read from ``VFINFER_*`` environment variables.

``VFINFER_TOKENS``: comma-separated ``user:token`` pairs (or ``VFINFER_TOKENS_FILE``: a JSON
object ``{"user": "token"}``).  Tokens are compared in constant time; a token maps to exactly
one user, and every job belongs to the user whose token submitted it. ``VFINFER_LINK_SECRET`` (at least 16
characters) keys the signed links of the HTML pages (``service.signing``); every API process behind one address
needs the same one, and without it each process draws its own at start.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, SecretStr, field_validator


class Settings(BaseModel):
    # a refused setting may be a token or the link secret: errors must not repeat it
    model_config = ConfigDict(hide_input_in_errors=True)

    data_dir: Path = Field(default=Path("vfinfer_data"), description="SQLite job table and Zarr stores")
    users: dict[str, str] = Field(default_factory=dict, description="{user: bearer token}")
    scheduler_address: str | None = Field(default=None, description="Dask scheduler; None = LocalCluster")
    n_workers: int = Field(default=2, ge=1, le=256)
    threads_per_worker: int = Field(default=1, ge=1, le=64)
    max_body_bytes: int = Field(default=8_000_000, ge=1_000)
    max_running_jobs: int = Field(default=4, ge=1, le=64, description="jobs driven concurrently")
    max_active_jobs_per_user: int = Field(default=50, ge=1)
    allow_toy_model: bool = Field(
        default=False, description="accept jobs for models registered as test doubles (worker.models)"
    )
    link_secret: SecretStr | None = Field(
        default=None, description="HMAC key of signed page links; None = random per process"
    )
    link_ttl_s: int = Field(default=300, ge=10, le=3600, description="how long a signed page link stays valid (s)")

    @field_validator("users")
    @classmethod
    def _tokens(cls, v: dict[str, str]) -> dict[str, str]:
        seen = set()
        for user, tok in v.items():
            if not user or len(tok) < 8:
                raise ValueError(f"token of user {user!r} must have at least 8 characters")
            if tok in seen:
                raise ValueError("two users share a token")
            seen.add(tok)
        return v

    @field_validator("link_secret")
    @classmethod
    def _link_secret(cls, v: SecretStr | None) -> SecretStr | None:
        if v is not None and len(v.get_secret_value()) < 16:
            raise ValueError("the link secret (VFINFER_LINK_SECRET) must have at least 16 characters")
        return v

    @property
    def db_path(self) -> Path:
        return self.data_dir / "jobs.sqlite"

    @property
    def stores_dir(self) -> Path:
        return self.data_dir / "stores"

    @classmethod
    def from_env(cls, **overrides) -> Settings:
        env = os.environ
        kw: dict = {}
        if "VFINFER_DATA_DIR" in env:
            kw["data_dir"] = Path(env["VFINFER_DATA_DIR"])
        users: dict[str, str] = {}
        if env.get("VFINFER_TOKENS_FILE"):
            users.update(json.loads(Path(env["VFINFER_TOKENS_FILE"]).read_text()))
        for pair in filter(None, (p.strip() for p in env.get("VFINFER_TOKENS", "").split(","))):
            user, _, tok = pair.partition(":")
            users[user.strip()] = tok.strip()
        if users:
            kw["users"] = users
        for key, name in (("scheduler_address", "VFINFER_SCHEDULER"),):
            if env.get(name):
                kw[key] = env[name]
        for key, name in (
            ("n_workers", "VFINFER_N_WORKERS"),
            ("threads_per_worker", "VFINFER_THREADS"),
            ("max_body_bytes", "VFINFER_MAX_BODY_BYTES"),
            ("max_running_jobs", "VFINFER_MAX_RUNNING_JOBS"),
            ("max_active_jobs_per_user", "VFINFER_MAX_ACTIVE_JOBS_PER_USER"),
        ):
            if env.get(name):
                kw[key] = int(env[name])
        if env.get("VFINFER_LINK_SECRET"):
            kw["link_secret"] = env["VFINFER_LINK_SECRET"]
        if env.get("VFINFER_LINK_TTL_S"):
            kw["link_ttl_s"] = int(env["VFINFER_LINK_TTL_S"])
        if env.get("VFINFER_ALLOW_TOY"):
            kw["allow_toy_model"] = env["VFINFER_ALLOW_TOY"].lower() in ("1", "true", "yes")
        kw.update(overrides)
        return cls(**kw)
