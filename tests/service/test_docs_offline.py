"""The API documentation works without internet: /docs and /redoc load their scripts and styles from the
service itself (fastapi-offline's packaged Swagger UI and ReDoc), and every endpoint has a summary."""

from __future__ import annotations

import re

import pytest
from fastapi.testclient import TestClient
from svc_helpers import TOKENS

EXTERNAL = re.compile(r"""(?:src|href)\s*=\s*["']?(?:https?:)?//""", re.I)


class NoCluster:
    """Stands in for the Dask client: nothing is run here."""


@pytest.fixture
def http(tmp_path):
    from service.main import create_app
    from service.settings import Settings

    settings = Settings(data_dir=tmp_path / "data", users=TOKENS)
    with TestClient(create_app(settings, client=NoCluster())) as c:
        yield c


@pytest.mark.parametrize("page", ["/docs", "/redoc"])
def test_docs_pages_reference_no_external_host(http, page):
    r = http.get(page)
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    html = r.text
    assert not EXTERNAL.search(html) and "http://" not in html and "https://" not in html, html
    assert "cdn" not in html.lower() and "fonts.googleapis" not in html
    assets = re.findall(r"""(?:src|href)\s*=\s*["']([^"']+)["']""", html)
    assert assets, html
    for a in assets:  # every asset the page loads is served here
        assert a.startswith("/"), a
        got = http.get(a)
        assert got.status_code == 200 and len(got.content) > 100, a


def test_every_endpoint_has_a_summary(http):
    spec = http.get("/openapi.json").json()
    missing = [
        f"{m.upper()} {p}"
        for p, ops in spec["paths"].items()
        for m, op in ops.items()
        if not op.get("summary") or op["summary"] == op.get("operationId")
    ]
    assert not missing, missing
    auto = [
        f"{m.upper()} {p}: {op['summary']}"
        for p, ops in spec["paths"].items()
        for m, op in ops.items()
        if re.fullmatch(r"(?:[A-Z][a-z]*\s?)+", op["summary"])
    ]  # FastAPI's title-cased function name
    assert not auto, auto
