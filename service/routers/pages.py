"""The service's home page: the caller's jobs as HTML, each finished one linked to its report by a fresh
signed link, and the diagnoses of those jobs, each finished one linked to its diagnosis report; without
credentials, a page that says how to get in. Nothing on it loads from another host
and nothing runs a script (``report.PAGE_HEADERS``)."""

from __future__ import annotations

import json
import time
from datetime import UTC, datetime
from html import escape
from typing import Annotated

from fastapi import APIRouter, Query, Request, status
from fastapi.responses import HTMLResponse

from ..deps import ManagerDep, SettingsDep, UserDep
from ..report import PAGE_HEADERS, html_page
from ..signing import (
    Exp,
    LinkError,
    LinkOut,
    OptionalUserDep,
    Sig,
    Signer,
    SignerDep,
    jobs_scope,
    link_out,
    report_scope,
)
from .diagnose import diagnosis_report_scope, get_diagnosis

router = APIRouter(tags=["pages"])


def _ago(s: float) -> str:
    s = max(0, int(s))
    if s < 60:
        return f"{s} s ago"
    if s < 3600:
        return f"{s // 60} min ago"
    if s < 172_800:
        return f"{s // 3600} h {s % 3600 // 60:02d} min ago"
    return f"{s // 86_400} days ago"


def utc(epoch: float, fmt: str = "%Y-%m-%d %H:%M UTC") -> str:
    """The server cannot know the reader's time zone, so its pages say UTC."""
    return datetime.fromtimestamp(epoch, tz=UTC).strftime(fmt)


def when(epoch: float | None, now: float) -> str:
    """``2026-11-03 14:02 UTC (5 min ago)``."""
    return "–" if epoch is None else f"{utc(epoch)} ({_ago(now - epoch)})"


def _duration(s: float | None) -> str:
    if s is None:
        return "–"
    return f"{s:.1f} s" if s < 60 else f"{int(s) // 60} min {int(s) % 60:02d} s"


def _sampler(spec_json: str) -> tuple[str, str]:
    """The job's sampler and model, read from its stored spec without validating it again."""
    try:
        spec = json.loads(spec_json)
    except ValueError:
        return "?", "?"
    samp = spec.get("sampler") or {}
    size = samp.get("n_particles") or samp.get("n_samples")
    kind = str(samp.get("kind", "?")).upper() + (f", {size:,}" if isinstance(size, int) else "")
    return kind, str(spec.get("model", "fe")).upper()


def _page(title: str, body: str, code: int = status.HTTP_200_OK) -> HTMLResponse:
    return HTMLResponse(html_page(title, body), status_code=code, headers=PAGE_HEADERS)


def sign_in_page(reason: str | None = None, code: int = status.HTTP_200_OK) -> HTMLResponse:
    """How to open the pages: the API's bearer tokens cannot ride on a link, so a token asks for a signed one."""
    why = f"<div class='warn'>{escape(reason)}</div>" if reason else ""
    body = f"""{why}
<p>This service lists your inference jobs here and shows each finished job's report. The API authenticates
with a bearer token, which a browser cannot send on a plain link, so open these pages with a
<strong>short-lived signed link</strong> that your token asks for:</p>
<ul>
<li>your jobs: <code>vfinfer report --open --url URL --token TOKEN</code>, or
<code>POST /page-link</code> with <code>Authorization: Bearer TOKEN</code>;</li>
<li>one finished job's report: <code>vfinfer report JOB_ID --open</code>, or
<code>POST /jobs/JOB_ID/report-link</code>.</li>
</ul>
<p>Each answer holds a <code>url</code> to open within a few minutes:</p>
<pre>curl -s -X POST -H "Authorization: Bearer $VFINFER_TOKEN" URL/page-link</pre>
<p>Tokens are configured on the service (<code>VFINFER_TOKENS</code>). The API itself is described at
<a href='/docs'>/docs</a> and <a href='/redoc'>/redoc</a>.</p>"""
    return _page("vfinfer", body, code)


def diagnoses_of(jobs: list[dict], user: str, manager, request: Request) -> list[tuple[str, object]]:
    """``(job id, DiagnosisStatus)`` of every finished finite-element job of ``user`` that has a diagnosis, as
    ``GET /jobs/{id}/diagnosis`` answers it, so the page never disagrees with the API wherever diagnoses are
    kept."""
    out = []
    for r in sorted(jobs, key=lambda r: -r["created"]):
        if r["state"] != "done" or _sampler(r["spec"])[1] != "FE":  # only such jobs can be diagnosed
            continue
        st = get_diagnosis(r["id"], user, manager, request)
        if st.state != "none":
            out.append((r["id"], st))
    return out


def _diagnosis_row(jid: str, st, signer: Signer, now: float) -> str:
    state, verdict, sims, run_s, link = escape(st.state), "–", "–", None, "–"
    if st.state == "running" and st.progress:
        p = st.progress
        where = " ".join(str(x) for x in (p.get("stage"), p.get("entry")) if x)
        if p.get("step") and p.get("steps"):
            where += f" ({p['step']} of {p['steps']})"
        state += f"<br><span class='muted'>{escape(where)}</span>"
        sims, run_s = p.get("simulations"), p.get("elapsed_s")
    elif st.state == "failed" and st.error:
        state += f"<br><span class='muted'>{escape(st.error[:300])}</span>"
    elif st.state == "done":
        rep = st.report or {}
        verdict = escape(str(rep.get("verdict") or "–"))
        sims, run_s = rep.get("n_simulations"), rep.get("wall_s")
        path = f"/jobs/{jid}/diagnosis/report"
        link = f"<a href='{escape(signer.sign(diagnosis_report_scope(jid), path, now=now).path)}'>diagnosis report</a>"
    sims = f"{sims:,}" if isinstance(sims, int) else "–"
    run = _duration(float(run_s)) if isinstance(run_s, (int, float)) else "–"
    return (
        f"<tr><td><code>{escape(jid)}</code></td><td>{state}</td><td>{verdict}</td><td class='n'>{sims}</td>"
        f"<td class='n'>{run}</td><td>{link}</td></tr>"
    )


def jobs_page(
    user: str,
    jobs: list[dict],
    signer: Signer,
    now: float,
    link_expires: int | None,
    diagnoses: list[tuple[str, object]] = (),
) -> HTMLResponse:
    rows = []
    for r in sorted(jobs, key=lambda r: -r["created"]):
        sampler, model = _sampler(r["spec"])
        run_s = ((r["finished"] or now) - r["started"]) if r["started"] else None
        progress = f"{r['n_done']:,}/{r['n_total']:,}" if r["n_total"] else "–"
        state = escape(r["state"])
        if r["state"] == "failed" and r["error"]:
            state += f"<br><span class='muted'>{escape(str(r['error'])[:300])}</span>"
        if r["state"] == "done":
            link = signer.sign(report_scope(r["id"]), f"/jobs/{r['id']}/report", now=now)
            report = f"<a href='{escape(link.path)}'>report</a>"
        else:
            report = "–"
        rows.append(
            f"<tr><td><code>{escape(r['id'])}</code></td><td>{state}</td><td>{escape(when(r['created'], now))}"
            f"</td><td>{escape(sampler)}</td><td>{escape(model)}</td><td class='n'>{progress}</td>"
            f"<td class='n'>{_duration(run_s)}</td><td>{report}</td></tr>"
        )
    head = "".join(
        f"<th>{h}</th>" for h in ("job", "state", "submitted", "sampler", "model", "simulations", "run time", "")
    )
    table = (
        f"<table><tr>{head}</tr>{''.join(rows)}</table>"
        if rows
        else "<p>No jobs yet: <code>vfinfer submit GAW.csv</code> or <code>POST /jobs</code> starts one.</p>"
    )
    if diagnoses:
        dhead = "".join(f"<th>{h}</th>" for h in ("job", "diagnosis", "verdict", "simulations", "run time", ""))
        table += (
            "<h2>Diagnoses</h2><p class='muted'>Which physics the model misses, per diagnosed job "
            "(<code>vfinfer diagnosis</code>, <code>POST /jobs/{id}/diagnose</code>).</p>"
            f"<table><tr>{dhead}</tr>{''.join(_diagnosis_row(j, st, signer, now) for j, st in diagnoses)}"
            "</table>"
        )
    done = sum(r["state"] == "done" for r in jobs) + sum(st.state == "done" for _, st in diagnoses)
    notes = []
    if done:
        notes.append(
            f"The report links are valid for {_duration(signer.ttl_s)}, until "
            f"{utc(now + signer.ttl_s, '%H:%M:%S UTC')}; reloading the page makes new ones."
        )
    if link_expires is not None:
        notes.append(
            f"This page's own link expires at {utc(link_expires, '%H:%M:%S UTC')}; "
            "<code>vfinfer report</code> or <code>POST /page-link</code> makes a new one."
        )
    body = (
        f"<p class='muted'>{len(jobs)} job(s) of <strong>{escape(user)}</strong>, newest first; times in UTC."
        f"</p>{table}<p class='muted'>{' '.join(notes)}</p>"
        "<p class='muted'>API: <a href='/docs'>/docs</a>, <a href='/redoc'>/redoc</a>.</p>"
    )
    return _page("vfinfer jobs", body)


@router.get(
    "/",
    response_class=HTMLResponse,
    summary="Your jobs and their diagnoses as an HTML page, with signed links to the finished jobs' and "
    "diagnoses' reports (bearer token or a signed link from POST /page-link); without either, a page "
    "saying how to sign in",
    responses={
        401: {"description": "a wrong bearer token"},
        403: {"description": "a signed link that is expired, altered or made for another user"},
    },
)
def home(
    manager: ManagerDep,
    settings: SettingsDep,
    signer: SignerDep,
    user: OptionalUserDep,
    request: Request,
    link_user: Annotated[
        str | None, Query(alias="user", max_length=200, description="signed link: whose jobs (with exp and sig)")
    ] = None,
    exp: Exp = None,
    sig: Sig = None,
) -> HTMLResponse:
    now = time.time()
    link_expires = None
    if user is None:
        if link_user is None and exp is None and sig is None:
            return sign_in_page()
        try:
            if link_user is None:
                raise LinkError("incomplete signed link: it needs user, exp and sig; ask for a new link")
            signer.verify(jobs_scope(link_user), exp, sig, now=now)
        except LinkError as exc:
            return sign_in_page(str(exc), status.HTTP_403_FORBIDDEN)
        if link_user not in settings.users:  # a user removed from the service loses its links too
            return sign_in_page("this link's user has no access to this service", status.HTTP_403_FORBIDDEN)
        user, link_expires = link_user, exp
    jobs = manager.db.list(owner=user)
    return jobs_page(user, jobs, signer, now, link_expires, diagnoses_of(jobs, user, manager, request))


@router.post(
    "/page-link",
    response_model=LinkOut,
    summary="A short-lived signed link to your jobs page (/) that a browser opens without the bearer token",
)
def page_link(user: UserDep, signer: SignerDep, request: Request) -> LinkOut:
    return link_out(request, signer.sign(jobs_scope(user), "/", {"user": user}))
