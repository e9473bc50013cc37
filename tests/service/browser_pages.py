"""The service's pages in a real browser: a service holding a finished job and a finished diagnosis, and a
headless Chromium (the system's own, driven by Playwright, which downloads no browser) that opens each page,
reads what a person would see and writes a screenshot.

Shared by ``tests/service/test_browser.py`` (every page loads, every image loads, no console error) and
``scripts/screenshots.py`` (the pictures in docs/img/), so the README shows what the test checked.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from svc_helpers import TOKENS, ServerThread, auth, done_fe_job, store_diagnosis, wait_done

#: The pages, in the order they are opened; each value says what to wait for before the page counts as shown
#: (Swagger UI renders its operations from /openapi.json after the load event).
PAGES = {"job_report": "h1", "diagnosis_report": "h1", "docs": ".swagger-ui .opblock"}
#: Where Debian, Ubuntu and Chrome put the browser; ``VFINFER_CHROMIUM`` names another.
CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
OWNER = "alice"
LINK_SECRET = "browser-test-secret-0123456789"


def chromium_path() -> str | None:
    """The Chromium executable to drive, or None when this machine has none."""
    env = os.environ.get("VFINFER_CHROMIUM")
    if env:
        return env if Path(env).is_file() else None
    for name in CANDIDATES:
        found = shutil.which(name)
        if found:
            return found
    return None


@dataclass
class PageView:
    """What the browser saw of one page."""

    name: str
    url: str
    status: int
    title: str
    images: list[dict]  # {"src": first 60 characters, "width": naturalWidth, "complete": bool}
    console_errors: list[str] = field(default_factory=list)
    failed_requests: list[str] = field(default_factory=list)
    screenshot: Path | None = None
    height_px: int = 0

    @property
    def broken_images(self) -> list[dict]:
        return [i for i in self.images if not (i["complete"] and i["width"] > 0)]

    def problems(self) -> list[str]:
        """Everything a person would call broken; empty for a good page."""
        out = []
        if self.status != 200:
            out.append(f"HTTP {self.status}")
        out += [f"image not loaded: {i['src']}" for i in self.broken_images]
        out += [f"console error: {m}" for m in self.console_errors]
        out += [f"request failed: {r}" for r in self.failed_requests]
        return out


@dataclass
class Site:
    """A running service with one finished job and one finished diagnosis of ``OWNER``."""

    url: str
    http: object
    job_id: str
    diagnosis_job_id: str

    def page_urls(self) -> dict[str, str]:
        """Each page's address; the two reports by a fresh signed link, as a person opens them (a browser sends
        no bearer token)."""

        def link(path: str) -> str:
            r = self.http.post(path, headers=auth(OWNER))
            r.raise_for_status()
            return self.url + r.json()["url"]

        return {
            "job_report": link(f"/jobs/{self.job_id}/report-link"),
            "diagnosis_report": link(f"/jobs/{self.diagnosis_job_id}/diagnosis/report-link"),
            "docs": self.url + "/docs",
        }


@contextmanager
def pages_service(
    data_dir: Path,
    client,
    job_spec: dict,
    diagnosis: dict | None = None,
    diagnosis_png: bytes | None = None,
    job_timeout_s: float = 600.0,
) -> Iterator[Site]:
    """The service on 127.0.0.1 with ``client``'s Dask cluster, ``job_spec`` run to the end as ``OWNER``'s job
    and a finished diagnosis stored beside a finished FE job: ``diagnosis`` (a report as ``vfinfer diagnose``
    writes ``diagnosis.json``; default: the sample of tests/service/test_report_diagnose.py) with its figure
    ``diagnosis_png`` (default: the job's own fit figure, a real PNG)."""
    import httpx

    from service.main import create_app
    from service.settings import Settings

    settings = Settings(data_dir=Path(data_dir), users=TOKENS, allow_toy_model=True, link_secret=LINK_SECRET)
    with ServerThread(create_app(settings, client=client)) as srv, httpx.Client(base_url=srv.url, timeout=60) as http:
        r = http.post("/jobs", json=job_spec, headers=auth(OWNER))
        assert r.status_code == 202, r.text
        job_id = r.json()["id"]
        st = wait_done(http, job_id, OWNER, timeout=job_timeout_s)
        assert st["state"] == "done", st
        if diagnosis is None:
            from test_report_diagnose import REPORT

            diagnosis = REPORT
        if diagnosis_png is None:
            fig = http.get(f"/jobs/{job_id}/figures/gaw_fit", headers=auth(OWNER))
            fig.raise_for_status()
            diagnosis_png = fig.content
        diag_job = done_fe_job(settings, owner=OWNER)
        store_diagnosis(settings, diag_job, report=diagnosis, png=diagnosis_png)  # as a finished diagnosis leaves it
        yield Site(srv.url, http, job_id, diag_job)


def open_pages(
    urls: dict[str, str], out_dir: Path, chromium: str, width: int = 1280, timeout_ms: int = 20_000
) -> dict[str, PageView]:
    """Open each page in one headless Chromium, wait until it is shown, and write ``out_dir/<name>.png`` (the
    whole page). Console errors, uncaught exceptions and failed or refused requests are collected per page."""
    from playwright.sync_api import sync_playwright

    out_dir.mkdir(parents=True, exist_ok=True)
    views = {}
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium, headless=True)
        try:
            ctx = browser.new_context(viewport={"width": width, "height": 900})
            for name, url in urls.items():
                page = ctx.new_page()
                errors, failed = [], []
                page.on("console", lambda m, errors=errors: errors.append(m.text) if m.type == "error" else None)
                page.on("pageerror", lambda e, errors=errors: errors.append(f"uncaught: {e}"))
                page.on("requestfailed", lambda r, failed=failed: failed.append(f"{r.url[:100]} ({r.failure})"))
                page.on(
                    "response",
                    lambda r, failed=failed: (
                        failed.append(f"{r.url[:100]} (HTTP {r.status})") if r.status >= 400 else None
                    ),
                )
                resp = page.goto(url, wait_until="load", timeout=timeout_ms)
                page.wait_for_selector(PAGES.get(name, "body"), timeout=timeout_ms)
                page.wait_for_load_state("networkidle", timeout=timeout_ms)
                images = page.evaluate(
                    "() => Array.from(document.images).map(i => ({src: i.src.slice(0, 60), "
                    "width: i.naturalWidth, complete: i.complete}))"
                )
                shot = out_dir / f"{name}.png"
                page.screenshot(path=str(shot), full_page=True)
                views[name] = PageView(
                    name,
                    url,
                    resp.status if resp else 0,
                    page.title(),
                    images,
                    errors,
                    failed,
                    shot,
                    page.evaluate("() => document.documentElement.scrollHeight"),
                )
                page.close()
        finally:
            browser.close()
    return views
