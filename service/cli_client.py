"""``vfinfer`` as a client of a running service: submit, list, status, cancel, fetch, diagnosis and report links.

A refused request (HTTP 4xx: unknown job, bad token, invalid job) is a user error: one ``error:`` line
with the service's own message, exit 2. A service that cannot be reached is one too; a server error
(5xx) exits 1."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.table import Table

from .cli_common import check_out, choice, fail, human_duration, human_time, staged_output, warn
from .cli_options import (
    AreaScale,
    Contact,
    ContactLayer,
    Discard,
    Dt,
    Duration,
    Fix,
    Fps,
    ForceReach,
    Measure,
    Mesh,
    Model,
    N,
    Noise,
    Out,
    Overwrite,
    Particles,
    Prior,
    PriorSet,
    Runs,
    Sampler,
    Screen,
    Seed,
    SigmaE,
    Token,
    Uncalibrated,
    Url,
    parse_area_scale,
)

console = Console()
JobId = Annotated[str, typer.Argument(help="job id printed by 'vfinfer submit' (32 characters)")]
FIGURES = ("gaw_fit", "corner", "contact_pressure")


def _message(r) -> str:
    """The service's own words for a refused request."""
    try:
        d = r.json()
    except ValueError:
        return r.text[:300] or r.reason_phrase
    if isinstance(d, dict):
        if d.get("message"):
            return str(d["message"])
        det = d.get("detail")
        if isinstance(det, list):
            return "; ".join(
                f"{'.'.join(str(p) for p in e.get('loc', []) if p != 'body')}: {e.get('msg')}"
                for e in det
                if isinstance(e, dict)
            )
        if det is not None:
            return str(det)
    return str(d)[:300]


class Service:
    """An authenticated connection to the service; every failure becomes one error line."""

    def __init__(self, url: str, token: str | None):
        import httpx

        if not url.startswith(("http://", "https://")) or len(url.split("://", 1)[1].strip("/")) == 0:
            raise fail(f"--url must look like http://host:port, got {url!r}")
        if not token or not token.strip():
            raise fail("no token: pass --token or set VFINFER_TOKEN")
        self.url = url.rstrip("/")
        try:
            self.http = httpx.Client(
                base_url=self.url, headers={"Authorization": f"Bearer {token.strip()}"}, timeout=60
            )
        except (ValueError, httpx.InvalidURL) as exc:
            raise fail(f"--url {url!r}: {exc}") from None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.http.close()

    def request(self, method: str, path: str, ok_missing: bool = False, **kw):
        """The response; 4xx -> exit 2 and 5xx -> exit 1, each with one error line (with ``ok_missing``, a 404
        is returned, for optional products)."""
        import httpx

        try:
            r = self.http.request(method, path, **kw)
        except httpx.InvalidURL as exc:
            raise fail(f"--url {self.url!r}: {exc}") from None
        except httpx.HTTPError as exc:
            raise fail(f"cannot reach the service at {self.url}: {type(exc).__name__}: {exc or 'no answer'}") from None
        if ok_missing and r.status_code == 404:
            return r
        if r.status_code >= 500:
            raise fail(f"the service failed (HTTP {r.status_code}): {_message(r)}", code=1)
        if r.status_code >= 400:
            raise fail(f"the service refused {method} {path} (HTTP {r.status_code}): {_message(r)}")
        return r

    def json(self, method: str, path: str, **kw) -> dict:
        return self.request(method, path, **kw).json()


def check_job_id(job_id: str) -> str:
    from .deps import JOB_ID_RE

    if not JOB_ID_RE.match(job_id):
        raise fail(f"{job_id!r} is not a job id (32 letters, digits, '-' or '_', as printed by 'vfinfer submit')")
    return job_id


# ------------------------------------------------------------------------------------ commands
def submit(
    gaw: Annotated[Path, typer.Argument(help="GAW file: CSV (time_s,area_mm2), NPY or NPZ; see README")],
    url: Url = "http://127.0.0.1:8000",
    token: Token = None,
    fps: Fps = None,
    sampler: Sampler = "smc",
    n: N = 2000,
    particles: Particles = 200,
    mesh: Mesh = "coarse",
    dt: Dt = 5e-5,
    duration: Duration = 0.55,
    discard: Discard = 0.25,
    sigma_e: SigmaE = 1.0,
    seed: Seed = 0,
    prior: Prior = None,
    fix: Fix = None,
    model: Model = "fe",
    noise: Noise = "fixed",
    measure: Measure = None,
    force_reach: ForceReach = False,
    screen: Screen = None,
    prior_set: PriorSet = "paper",
    area_scale: AreaScale = None,
    uncalibrated: Uncalibrated = False,
    contact: Contact = "projection",
    contact_layer_mm: ContactLayer = 0.1,
    runs: Runs = 1,
) -> None:
    """Submit an inference job to a running service; prints the job id (and the service's warnings)."""
    from .cli_spec import build_spec, note_is

    spec = build_spec(
        gaw,
        fps,
        sampler,
        n,
        particles,
        mesh,
        dt,
        duration,
        discard,
        sigma_e,
        seed,
        prior,
        fix,
        model=model,
        noise=noise,
        measure=measure,
        force_reach=force_reach,
        screen=screen,
        prior_set=prior_set,
        area_scale=parse_area_scale(area_scale, uncalibrated),
        contact=contact,
        contact_layer_mm=contact_layer_mm,
        runs=runs,
    )
    with Service(url, token) as svc:
        d = svc.json("POST", "/jobs", content=spec.to_json(), headers={"Content-Type": "application/json"})
    for w in d.get("warnings", []):
        warn(w)
    note_is(sampler)
    if d.get("expected_simulations"):  # on stderr: stdout ends with the id, which scripts read
        lo, hi = d["expected_simulations"]
        typer.echo(f"expected: {lo:,} simulations" if lo == hi else f"expected: {lo:,}-{hi:,} simulations", err=True)
    console.print(d["id"])


def expected_lines(e: dict | None) -> list[str]:
    """The service's announced cost of a diagnosis (``DiagnoseStarted.expected``) as the lines ``vfinfer
    diagnose`` prints, without minutes: the service does not time its workers."""
    from vfcore.diagnose.expected import ExpectedCost

    if not e:
        return []
    cost = ExpectedCost(
        floor=tuple(e["floor_simulations"]),
        catalogue=tuple(e["catalogue_simulations"]),
        floor_minutes=None,
        catalogue_minutes=None,
        seconds_per_simulation=None,
        workers=1,
        base_fits=int(e["base_fits"]),
        guide=tuple(e.get("scaled_for") or ()),
    )
    return cost.lines(given="job's posterior")


def _progress(d: dict) -> str:
    p = d["progress"]
    tot = p["simulations_total"] or 0
    pct = f" ({100 * p['simulations_done'] / tot:.0f} %)" if tot else ""
    return f"{p['simulations_done']:,}/{tot:,} simulations{pct}"


def print_status(d: dict) -> None:
    t = d["timings"]
    ess = f"  ESS {d['ess']:.1f}" if d.get("ess") is not None else ""
    console.print(f"{d['id']}  {d['state']}  {_progress(d)}{ess}", highlight=False)
    console.print(
        f"  {d['sampler'].upper()} sampler, {d['model'].upper()} model; submitted {human_time(t.get('created'))}",
        highlight=False,
    )
    if t.get("started"):
        running = "ran" if t.get("finished") else "running for"
        console.print(
            f"  waited {human_duration(t.get('queued_s'))} in the queue, {running} "
            f"{human_duration(t.get('running_s'))}"
            + (f", finished {human_time(t['finished'])}" if t.get("finished") else ""),
            highlight=False,
        )
    else:
        console.print(f"  queued for {human_duration(t.get('queued_s'))}", highlight=False)


def status(
    job_id: JobId,
    url: Url = "http://127.0.0.1:8000",
    token: Token = None,
    wait: Annotated[bool, typer.Option(help="poll every 2 s until the job ends")] = False,
) -> None:
    """Show a job's state, progress (simulations done), ESS and times (local time, and how long ago)."""
    check_job_id(job_id)
    with Service(url, token) as svc:
        while True:
            d = svc.json("GET", f"/jobs/{job_id}")
            if not wait or d["state"] in ("done", "failed", "cancelled"):
                break
            console.print(f"{d['id']}  {d['state']}  {_progress(d)}", highlight=False)
            time.sleep(2)
    print_status(d)
    for w in d.get("warnings", []):
        warn(w)
    if d.get("error"):
        console.print(f"job failed: {d['error']}", highlight=False, soft_wrap=True)


def list_jobs(
    url: Url = "http://127.0.0.1:8000",
    token: Token = None,
    state: Annotated[
        Optional[str],
        typer.Option(
            parser=choice("queued", "running", "done", "failed", "cancelled"),
            metavar="[queued|running|done|failed|cancelled]",
            help="only jobs in this state",
        ),
    ] = None,
) -> None:
    """List your jobs on the service, newest first: id, state, progress, when submitted, run time."""
    with Service(url, token) as svc:
        jobs = svc.json("GET", "/jobs")
    jobs = [j for j in jobs if state is None or j["state"] == state]
    jobs.sort(key=lambda j: -(j["timings"].get("created") or 0))
    if not jobs:
        console.print("no jobs" + (f" in state {state}" if state else ""))
        return
    t = Table(title=f"{len(jobs)} job(s)")
    for col in ("id", "state", "progress", "sampler", "submitted", "run time"):
        t.add_column(col, no_wrap=col == "id")
    for j in jobs:
        tm = j["timings"]
        t.add_row(
            j["id"],
            j["state"],
            _progress(j),
            j["sampler"],
            human_time(tm.get("created")),
            human_duration(tm.get("running_s")),
        )
    console.print(t)


def cancel(job_id: JobId, url: Url = "http://127.0.0.1:8000", token: Token = None) -> None:
    """Cancel a queued or running job (DELETE /jobs/{id}); a finished job cannot be cancelled."""
    check_job_id(job_id)
    with Service(url, token) as svc:
        before = svc.json("GET", f"/jobs/{job_id}")["state"]
        if before in ("done", "failed"):
            raise fail(f"job {job_id} is already {before}; nothing to cancel")
        d = svc.json("DELETE", f"/jobs/{job_id}")
    console.print(
        f"{d['id']}  {d['state']}" + ("  (it was already cancelled)" if before == "cancelled" else ""), highlight=False
    )


def fetch(
    job_id: JobId,
    url: Url = "http://127.0.0.1:8000",
    token: Token = None,
    out: Out = Path("vfinfer_output"),
    overwrite: Overwrite = False,
) -> None:
    """Download a finished job's posterior, samples (CSV + JSON metadata, NetCDF), figures and HTML report into
    OUT; print the posterior table."""
    from .cli_tables import print_table
    from .report import write_report

    check_job_id(job_id)
    check_out(out, overwrite)
    with Service(url, token) as svc:
        st = svc.json("GET", f"/jobs/{job_id}")
        if st["state"] != "done":
            raise fail(f"job {job_id} is {st['state']}, not done; 'vfinfer status {job_id} --wait' waits for it")
        summary = svc.json("GET", f"/jobs/{job_id}/posterior")
        with staged_output(out) as stage:
            (stage / "posterior.json").write_text(json.dumps(summary, indent=1, sort_keys=True))
            for path, fname in (
                (f"/jobs/{job_id}/samples", "samples.csv"),
                (f"/jobs/{job_id}/samples?format=meta", "samples.json"),
                (f"/jobs/{job_id}/samples?format=netcdf", "posterior.nc"),
                *((f"/jobs/{job_id}/figures/{n}", f"{n}.png") for n in FIGURES),
            ):
                r = svc.request("GET", path, ok_missing=True)
                if r.status_code == 200:
                    (stage / fname).write_bytes(r.content)
            write_report(stage, summary, title=f"vfinfer job {job_id}")
    print_table(summary, title=f"Posterior of job {job_id}")
    console.print(f"products written to {out}/; open {out / 'index.html'}", highlight=False)


def diagnosis(
    job_id: JobId,
    url: Url = "http://127.0.0.1:8000",
    token: Token = None,
    start: Annotated[bool, typer.Option(help="start a diagnosis of the finished job (POST)")] = False,
    candidates: Annotated[
        Optional[str], typer.Option(help="with --start: comma-separated catalogue entries (default: all implemented)")
    ] = None,
    particles: Annotated[
        Optional[int], typer.Option(help="with --start: SMC particles of each base fit (10-400)")
    ] = None,
    refit_particles: Annotated[
        Optional[int], typer.Option(help="with --start: particles of each refit (10-400)")
    ] = None,
    refit_start: Annotated[
        Optional[str], typer.Option(help="with --start: where each refit starts: prior, base or mixed")
    ] = None,
    max_refits: Annotated[Optional[int], typer.Option(help="with --start: most observation-level refits (0-6)")] = None,
    continuation: Annotated[
        Optional[bool],
        typer.Option("--continuation/--no-continuation", help="with --start: the window-continuation search"),
    ] = None,
    seed: Annotated[Optional[int], typer.Option(min=0, help="with --start: random seed")] = None,
    wait: Annotated[bool, typer.Option(help="poll, printing each new stage, until it ends")] = False,
    cancel: Annotated[bool, typer.Option(help="cancel the running diagnosis (DELETE)")] = False,
    out: Annotated[
        Optional[Path],
        typer.Option(help="when done: write diagnosis.json, diagnosis.png and index.html here and print the report"),
    ] = None,
) -> None:
    """A job's diagnosis on a running service: start it, follow it, cancel it, fetch it
    (POST/GET/DELETE /jobs/{id}/diagnosis; the same pipeline as ``vfinfer diagnose``)."""
    from .cli_diagnose import diagnose_request, print_report, stage_line

    check_job_id(job_id)
    if start and cancel:
        raise fail("--start and --cancel exclude each other")
    body = {
        k: v
        for k, v in (
            ("n_particles", particles),
            ("refit_particles", refit_particles),
            ("refit_start", refit_start),
            ("max_refits", max_refits),
            ("continuation", continuation),
            ("seed", seed),
        )
        if v is not None
    }
    if candidates:
        body["candidates"] = [c.strip() for c in candidates.split(",") if c.strip()]
    diagnose_request(**body)  # the service's bounds, checked before anything is sent
    if body and not start:
        raise fail("diagnosis settings (--candidates, --particles, ...) need --start")
    if out is not None and out.exists() and not out.is_dir():
        raise fail(f"--out {out} exists and is not a folder")
    with Service(url, token) as svc:
        if start:
            started = svc.json("POST", f"/jobs/{job_id}/diagnose", json=body or None)
            console.print(f"diagnosis of {job_id} started")
            for line in expected_lines(started.get("expected")):
                console.print(line, highlight=False, soft_wrap=True)
        if cancel:
            svc.request("DELETE", f"/jobs/{job_id}/diagnosis")
            console.print(f"diagnosis of {job_id} cancelling")
        last = None
        while True:
            d = svc.json("GET", f"/jobs/{job_id}/diagnosis")
            p = d.get("progress")
            if p and (p["stage"], p.get("entry")) != last:
                last = (p["stage"], p.get("entry"))
                console.print(stage_line(p), highlight=False)
            if not wait or d["state"] not in ("queued", "running"):
                break
            time.sleep(2)
        console.print(f"{job_id}  diagnosis {d['state']}")
        if d.get("error"):
            console.print(f"diagnosis failed: {d['error']}", highlight=False, soft_wrap=True)
        if d["state"] == "done" and out is not None:
            out.mkdir(parents=True, exist_ok=True)
            (out / "diagnosis.json").write_text(json.dumps(d["report"], indent=1))
            r = svc.request("GET", f"/jobs/{job_id}/diagnosis/figure", ok_missing=True)
            if r.status_code == 200:
                (out / "diagnosis.png").write_bytes(r.content)
            from .report_diagnose import write_diagnosis_report

            page = write_diagnosis_report(out, d["report"], title=f"vfinfer diagnosis of job {job_id}")
            print_report(d["report"])
            console.print(
                f"wrote {out / 'diagnosis.json'}"
                + (", diagnosis.png" if r.status_code == 200 else "")
                + f"; report: {page}",
                highlight=False,
            )
    if d["state"] == "failed":
        raise typer.Exit(1)


def report(
    job_id: Annotated[
        Optional[str],
        typer.Argument(help="a finished job's id (32 characters); without one, the link opens your jobs page"),
    ] = None,
    url: Url = "http://127.0.0.1:8000",
    token: Token = None,
    open_: Annotated[bool, typer.Option("--open", help="also open the link in the web browser")] = False,
) -> None:
    """Print a short-lived signed link to a finished job's HTML report (or to your jobs page) that a browser
    opens without the token; it stays valid for a few minutes."""
    import webbrowser

    if job_id is not None:
        check_job_id(job_id)
    with Service(url, token) as svc:
        d = svc.json("POST", f"/jobs/{job_id}/report-link" if job_id is not None else "/page-link")
        link = svc.url + d["url"]
    typer.echo(link)
    typer.echo(f"valid until {human_time(d['expires'])}", err=True)  # stdout holds only the link
    if open_ and not webbrowser.open(link):
        warn("no web browser could be started here; open the link above yourself")
