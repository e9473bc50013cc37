"""The HTML pages in a real headless Chromium: a finished job's report opened by its signed link, a diagnosis
report opened by its signed link, and the offline API docs each load, show every image (naturalWidth > 0), log
no console error and request nothing that fails. A screenshot of each page is written to ``$TEST_ARTIFACTS``
(else pytest's tmp dir) for a person to look at.

The browser is the system's Chromium (Debian's ``chromium``, installed by .ci/run), driven by Playwright;
without one the test is skipped and says so."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from browser_pages import PAGES, chromium_path, open_pages, pages_service
from svc_helpers import toy_spec

CHROMIUM = chromium_path()
pytestmark = pytest.mark.skipif(
    CHROMIUM is None,
    reason="no Chromium on this machine (apt-get install chromium, or VFINFER_CHROMIUM=/path/to/chrome)",
)


@pytest.fixture(scope="module")
def views(tmp_path_factory, dask_client):
    pytest.importorskip("playwright.sync_api", reason="playwright is not installed (the dev extra has it)")
    art = os.environ.get("TEST_ARTIFACTS")
    out = Path(art) / "browser" if art else tmp_path_factory.mktemp("screenshots")
    with pages_service(tmp_path_factory.mktemp("browser") / "data", dask_client, toy_spec(n=40, seed=3)) as site:
        t0 = time.perf_counter()
        views = open_pages(site.page_urls(), out, CHROMIUM)
        views["_seconds"] = time.perf_counter() - t0
        yield views


@pytest.mark.parametrize("name", list(PAGES))
def test_page_loads_with_every_image_and_no_console_error(views, name):
    v = views[name]
    assert not v.problems(), (v.url, v.problems())
    assert v.title and v.height_px > 300, (v.title, v.height_px)
    assert v.screenshot.stat().st_size > 10_000, v.screenshot  # a page was drawn, not a blank
    print(f"{name}: {v.screenshot} ({v.height_px} px high)")


def test_reports_show_their_figures(views):
    job, diag = views["job_report"], views["diagnosis_report"]
    assert len(job.images) == 3 and all(i["src"].startswith("data:image/png") for i in job.images), job.images
    assert job.url.split("?")[0].endswith(f"/jobs/{job.title.split()[-1]}/report"), (job.title, job.url)
    assert len(diag.images) == 1 and diag.images[0]["width"] > 100 and "diagnosis" in diag.title
    assert views["_seconds"] < 30, views["_seconds"]
