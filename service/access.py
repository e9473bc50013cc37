"""Which job records a request may read: the lookups every router shares (jobs, diagnosis).

A job that is missing or belongs to someone else is the same 404, so ids of other users' jobs are
not revealed; results exist only for a finished job (409 otherwise). An endpoint of one kind of job
(an inference's posterior, a job's diagnosis) answers 404 for a job of another kind.
"""

from __future__ import annotations

from fastapi import HTTPException, status


def own_job(manager, job_id: str, user: str, kind: str | None = "inference") -> dict:
    """The job's record if ``user`` owns it and it is of ``kind`` (None: any kind), else 404."""
    rec = manager.db.get(job_id, owner=user, kind=kind)
    if rec is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, "job not found")
    return rec


def done_job(manager, job_id: str, user: str) -> dict:
    """The record of ``user``'s finished job: 404 as :func:`own_job`, 409 while it is not done."""
    rec = own_job(manager, job_id, user)
    if rec["state"] != "done":
        raise HTTPException(status.HTTP_409_CONFLICT, f"job is {rec['state']}, not done")
    return rec


def page_reader(manager, job_id: str, user: str | None, signer, scope: str, exp, sig, how: str) -> str:
    """Whose view of a job's HTML page a request gets: the bearer token's user, else the job's owner when the
    request carries a valid signed link for ``scope`` (only the owner is ever given one). 401 with neither (the
    message names ``how`` to make a link), 403 for a link that does not open this page, 404 for no such job."""
    from .signing import LinkError, link_refused

    if user is not None:
        return user
    if exp is None and sig is None:
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED,
            f"missing bearer token or signed link ({how} makes a link a browser can open)",
            headers={"WWW-Authenticate": "Bearer"},
        )
    try:
        signer.verify(scope, exp, sig)
    except LinkError as exc:
        raise link_refused(exc) from None
    row = manager.db.get(job_id)
    if row is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, "job not found")
    return row["owner"]
