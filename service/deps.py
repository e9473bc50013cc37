"""Typed dependencies: settings, job manager, and the authenticated user (bearer token)."""

from __future__ import annotations

import hmac
import re
from typing import Annotated

from fastapi import Depends, HTTPException, Path, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from .manager import JobManager
from .settings import Settings

_bearer = HTTPBearer(auto_error=False, description="per-user bearer token (VFINFER_TOKENS)")

#: Shape of ids made by ``manager.new_job_id`` (checked before any lookup).
JOB_ID_RE = re.compile(r"^[A-Za-z0-9_-]{32}$")


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


def get_manager(request: Request) -> JobManager:
    return request.app.state.manager


def get_user(
    settings: Annotated[Settings, Depends(get_settings)],
    cred: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> str:
    if cred is None or cred.scheme.lower() != "bearer":
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED, "missing bearer token", headers={"WWW-Authenticate": "Bearer"}
        )
    given = cred.credentials.encode()
    user = None
    for name, tok in settings.users.items():  # constant time per comparison, no early exit
        if hmac.compare_digest(given, tok.encode()):
            user = name
    if user is None:
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED, "invalid bearer token", headers={"WWW-Authenticate": "Bearer"}
        )
    return user


def get_job_id(job_id: Annotated[str, Path(description="job id returned by POST /jobs")]) -> str:
    if not JOB_ID_RE.match(job_id):
        raise HTTPException(status.HTTP_404_NOT_FOUND, "job not found")
    return job_id


SettingsDep = Annotated[Settings, Depends(get_settings)]
ManagerDep = Annotated[JobManager, Depends(get_manager)]
UserDep = Annotated[str, Depends(get_user)]
JobIdDep = Annotated[str, Depends(get_job_id)]
