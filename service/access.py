"""Which job records a request may read: the lookups every router shares (jobs, diagnosis).

A job that is missing or belongs to someone else is the same 404, so ids of other users' jobs are
not revealed; results exist only for a finished job (409 otherwise).
"""
from __future__ import annotations

from fastapi import HTTPException, status


def own_job(manager, job_id: str, user: str) -> dict:
    """The job's record if ``user`` owns it, else 404."""
    rec = manager.db.get(job_id, owner=user)
    if rec is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, "job not found")
    return rec


def done_job(manager, job_id: str, user: str) -> dict:
    """The record of ``user``'s finished job: 404 as :func:`own_job`, 409 while it is not done."""
    rec = own_job(manager, job_id, user)
    if rec["state"] != "done":
        raise HTTPException(status.HTTP_409_CONFLICT, f"job is {rec['state']}, not done")
    return rec
