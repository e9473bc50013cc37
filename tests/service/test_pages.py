"""The HTML pages in a browser's terms: signed links that open a report or the jobs page without a bearer
header (and only that page, only for a few minutes), the jobs page listing only its owner's jobs with nothing
loaded from another host, and ``vfinfer report`` printing such a link."""

from __future__ import annotations

import json
import re
import time

import httpx
import pytest
from svc_helpers import TOKENS, ServerThread, auth, toy_spec, wait_done
from typer.testing import CliRunner

from service.cli import app
from service.signing import LinkError, Signer, jobs_scope, report_scope

SECRET = "pages-test-secret-0123456789"
#: A URL that leaves the service: an absolute or protocol-relative src/href, or a CSS url().
EXTERNAL = re.compile(r"""(?:src|href)\s*=\s*["']?(?:[a-z][a-z0-9+.-]*:)?//|url\(""", re.I)


@pytest.fixture(scope="module")
def svc(tmp_path_factory, dask_client):
    """One service for the module: a finished toy job each for alice and bob, and a failed one of alice's."""
    from service.db import JobDB
    from service.main import create_app
    from service.manager import new_job_id
    from service.settings import Settings

    settings = Settings(
        data_dir=tmp_path_factory.mktemp("pages") / "data",
        users=TOKENS,
        allow_toy_model=True,
        link_secret=SECRET,
        link_ttl_s=120,
    )
    with (
        ServerThread(create_app(settings, client=dask_client)) as srv,
        httpx.Client(base_url=srv.url, timeout=60) as http,
    ):
        srv.http, srv.settings = http, settings
        srv.jobs = {}
        for user in ("alice", "bob"):
            r = http.post("/jobs", json=toy_spec(n=40, seed=3), headers=auth(user))
            assert r.status_code == 202, r.text
            srv.jobs[user] = r.json()["id"]
        for user, jid in srv.jobs.items():
            assert wait_done(http, jid, user)["state"] == "done"
        db = JobDB(settings.db_path)  # a failed job, written as the manager would leave it
        srv.failed = new_job_id()
        db.insert(srv.failed, "alice", json.dumps(toy_spec(n=40)), 40)
        db.update(srv.failed, state="failed", error="toy <failure> for the page")
        db.close()
        yield srv


def _report_link(svc, user: str, job: str) -> str:
    r = svc.http.post(f"/jobs/{job}/report-link", headers=auth(user))
    assert r.status_code == 200, r.text
    d = r.json()
    assert d["url"].startswith(f"/jobs/{job}/report?") and d["absolute_url"] == svc.url + d["url"]
    assert d["expires_in_s"] == 120 and abs(d["expires"] - (time.time() + 120)) < 5
    return d["url"]


def _no_external_host(page: str) -> None:
    assert not EXTERNAL.search(page), EXTERNAL.search(page)
    assert "http://" not in page and "https://" not in page and "<script" not in page.lower()


# ------------------------------------------------------------------------------------ the signer alone
def test_signer_accepts_its_own_link_until_it_expires():
    s = Signer(SECRET.encode(), ttl_s=60)
    link = s.sign(report_scope("J" * 32), "/jobs/" + "J" * 32 + "/report", now=1_000_000)
    q = dict(p.split("=", 1) for p in link.path.split("?", 1)[1].split("&"))
    assert int(q["exp"]) == link.expires == 1_000_060
    s.verify(report_scope("J" * 32), link.expires, q["sig"], now=1_000_059)
    with pytest.raises(LinkError, match="expired at 1970-01-12 13:47:40 UTC"):
        s.verify(report_scope("J" * 32), link.expires, q["sig"], now=1_000_060)
    refusals = [
        (report_scope("K" * 32), link.expires, q["sig"]),  # another job
        (jobs_scope("alice"), link.expires, q["sig"]),  # another kind of page
        (report_scope("J" * 32), link.expires + 3600, q["sig"]),  # a longer life
        (report_scope("J" * 32), link.expires, q["sig"][:-1] + ("A" if q["sig"][-1] != "A" else "B")),
        (report_scope("J" * 32), link.expires, q["sig"] + "A"),
        (report_scope("J" * 32), link.expires, ""),
    ]
    for scope, exp, sig in refusals:
        with pytest.raises(LinkError, match="invalid link signature"):
            s.verify(scope, exp, sig, now=1_000_000)
    with pytest.raises(LinkError, match="invalid link signature"):  # another server's secret
        Signer(b"another-secret-0123456789").verify(report_scope("J" * 32), link.expires, q["sig"], now=1_000_000)
    with pytest.raises(LinkError, match="needs both exp and sig"):
        s.verify(report_scope("J" * 32), None, q["sig"], now=1_000_000)
    with pytest.raises(ValueError):
        Signer(b"short")


def test_secret_comes_from_settings_or_is_drawn_at_start(monkeypatch):
    from pydantic import ValidationError

    from service.settings import Settings

    drawn = [Signer.from_settings(Settings()) for _ in range(2)]
    link = drawn[0].sign(jobs_scope("alice"), "/", now=0)
    sig = link.path.rsplit("sig=", 1)[1]
    with pytest.raises(LinkError):  # each process without a configured secret draws its own
        drawn[1].verify(jobs_scope("alice"), link.expires, sig, now=0)
    monkeypatch.setenv("VFINFER_LINK_SECRET", SECRET)
    monkeypatch.setenv("VFINFER_LINK_TTL_S", "90")
    s = Settings.from_env()
    assert s.link_ttl_s == 90 and SECRET not in repr(s)
    a, b = Signer.from_settings(s), Signer.from_settings(Settings.from_env())
    link = a.sign(jobs_scope("alice"), "/", now=0)
    b.verify(jobs_scope("alice"), link.expires, link.path.rsplit("sig=", 1)[1], now=1)  # shared across processes
    with pytest.raises(ValidationError) as err:
        Settings(link_secret="too-short")
    assert "at least 16 characters" in str(err.value) and "too-short" not in str(err.value)


# ------------------------------------------------------------------------------------ the report by link
def test_signed_link_opens_the_report_without_a_bearer_header(svc):
    job = svc.jobs["alice"]
    url = _report_link(svc, "alice", job)
    with httpx.Client(base_url=svc.url, timeout=60) as browser:  # no Authorization header at all
        r = browser.get(url)
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html"), r.text
    assert "E_cover" in r.text and "data:image/png;base64," in r.text and job in r.text
    _no_external_host(r.text)
    assert "default-src 'none'" in r.headers["content-security-policy"]
    assert r.headers["referrer-policy"] == "no-referrer" and r.headers["cache-control"] == "no-store"
    with_token = svc.http.get(f"/jobs/{job}/report", headers=auth("alice"))  # the bearer still works
    assert with_token.status_code == 200 and with_token.text.count("<img") == r.text.count("<img")


def test_expired_tampered_and_other_job_links_are_refused(svc):
    alice, bob = svc.jobs["alice"], svc.jobs["bob"]
    url = _report_link(svc, "alice", alice)
    sig = url.rsplit("sig=", 1)[1]
    exp = int(re.search(r"exp=(\d+)", url).group(1))
    old = Signer(SECRET.encode(), ttl_s=120).sign(report_scope(alice), f"/jobs/{alice}/report", now=time.time() - 600)
    flipped = sig[:5] + ("x" if sig[5] != "x" else "y") + sig[6:]
    cases = {
        old.path: "expired at",
        url.replace(f"sig={sig}", f"sig={flipped}"): "invalid link signature",
        url.replace(f"exp={exp}", f"exp={exp + 3600}"): "invalid link signature",
        url.replace(alice, bob): "invalid link signature",  # alice's link, bob's job
        f"/jobs/{alice}/report?sig={sig}": "needs both exp and sig",
        f"/jobs/{alice}/report?exp={exp}": "needs both exp and sig",
    }
    for bad, words in cases.items():
        r = httpx.get(svc.url + bad, timeout=60)
        assert r.status_code == 403, (bad, r.text)
        detail = r.json()["detail"]
        assert words in detail and "\n" not in detail, (bad, detail)
    r = httpx.get(f"{svc.url}/jobs/{alice}/report", timeout=60)
    assert r.status_code == 401 and "report-link" in r.json()["detail"]
    r = httpx.get(f"{svc.url}{url}", headers={"Authorization": "Bearer wrong-token-0123"}, timeout=60)
    assert r.status_code == 401  # a wrong token is not rescued by a link beside it


def test_only_the_owner_of_a_finished_job_gets_a_link(svc):
    r = svc.http.post(f"/jobs/{svc.jobs['alice']}/report-link", headers=auth("bob"))
    assert r.status_code == 404  # as every endpoint: another's job does not exist
    assert svc.http.post(f"/jobs/{svc.jobs['alice']}/report-link").status_code == 401
    r = svc.http.post(f"/jobs/{svc.failed}/report-link", headers=auth("alice"))
    assert r.status_code == 409 and "failed" in r.json()["detail"]
    assert svc.http.post("/jobs/%2E%2E/report-link", headers=auth("alice")).status_code == 404


# ------------------------------------------------------------------------------------ the jobs page
def _ids(page: str) -> set[str]:
    return set(re.findall(r"<code>([A-Za-z0-9_-]{32})</code>", page))


def test_jobs_page_lists_only_the_owners_jobs(svc):
    r = svc.http.get("/", headers=auth("alice"))
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    page = r.text
    assert _ids(page) == {svc.jobs["alice"], svc.failed} and svc.jobs["bob"] not in page
    _no_external_host(page)
    assert "UTC (" in page and "ago)" in page and "IS, 40" in page and "TOY" in page
    assert "toy &lt;failure&gt; for the page" in page  # the failure, escaped
    assert "default-src 'none'" in r.headers["content-security-policy"]
    links = re.findall(r"href='(/jobs/[^']+/report\?[^']+)'", page)
    assert len(links) == 1 and svc.jobs["alice"] in links[0]  # the finished job only
    report = httpx.get(svc.url + links[0].replace("&amp;", "&"), timeout=60)  # a fresh signed link
    assert report.status_code == 200 and "E_cover" in report.text
    carol = svc.http.get("/", headers=auth("carol"))
    assert carol.status_code == 200 and not _ids(carol.text) and "No jobs yet" in carol.text


def test_jobs_page_by_signed_link_and_without_credentials(svc):
    r = svc.http.post("/page-link", headers=auth("alice"))
    assert r.status_code == 200
    url = r.json()["url"]
    assert url.startswith("/?user=alice&")
    page = httpx.get(svc.url + url, timeout=60)
    assert page.status_code == 200 and _ids(page.text) == {svc.jobs["alice"], svc.failed}
    assert "own link expires at" in page.text
    for bad, words in (
        (url.replace("user=alice", "user=bob"), "invalid link signature"),
        (url.split("&sig=")[0], "needs both exp and sig"),
        ("/?exp=1&sig=" + "A" * 43, "needs user, exp and sig"),
    ):
        r = httpx.get(svc.url + bad, timeout=60)
        assert r.status_code == 403 and words in r.text and "<html" in r.text, (bad, r.text[-800:])
        assert not _ids(r.text)
    anon = httpx.get(svc.url + "/", timeout=60)
    assert anon.status_code == 200 and anon.headers["content-type"].startswith("text/html")
    assert "Bearer" in anon.text and "vfinfer report" in anon.text and "/page-link" in anon.text
    assert "Traceback" not in anon.text and not _ids(anon.text)
    _no_external_host(anon.text)
    assert httpx.get(svc.url + "/", headers={"Authorization": "Bearer nope-nope-nope"}, timeout=60).status_code == 401


def test_pages_have_summaries_in_the_api_docs(svc):
    paths = svc.http.get("/openapi.json").json()["paths"]
    assert paths["/"]["get"]["summary"] and paths["/page-link"]["post"]["summary"]
    assert paths["/jobs/{job_id}/report-link"]["post"]["summary"]
    params = {p["name"] for p in paths["/jobs/{job_id}/report"]["get"]["parameters"]}
    assert {"exp", "sig"} <= params


# ------------------------------------------------------------------------------------ vfinfer report
def test_cli_prints_a_signed_link_and_opens_it(svc, monkeypatch):
    import webbrowser

    env = {"VFINFER_URL": svc.url, "VFINFER_TOKEN": TOKENS["alice"], "COLUMNS": "80"}
    job = svc.jobs["alice"]
    r = CliRunner().invoke(app, ["report", job], env=env)
    assert r.exit_code == 0, r.output
    lines = r.stdout.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{svc.url}/jobs/{job}/report?exp="), r.stdout
    assert r.stderr.startswith("valid until ")
    assert httpx.get(lines[0], timeout=60).status_code == 200
    opened = []
    monkeypatch.setattr(webbrowser, "open", lambda url: opened.append(url) or True)
    r = CliRunner().invoke(app, ["report", "--open"], env=env)  # no id: the jobs page
    assert r.exit_code == 0 and opened == [r.stdout.strip()] and "/?user=alice&" in opened[0], r.output
    monkeypatch.setattr(webbrowser, "open", lambda url: False)
    r = CliRunner().invoke(app, ["report", job, "--open"], env=env)
    assert r.exit_code == 0 and "warning: no web browser" in r.stderr
    r = CliRunner().invoke(app, ["report", job], env={**env, "VFINFER_TOKEN": TOKENS["bob"]})
    err = r.stderr.strip().splitlines()
    assert r.exit_code == 2 and len(err) == 1 and "404" in err[0] and "Traceback" not in r.output
    r = CliRunner().invoke(app, ["report", svc.failed], env=env)
    assert r.exit_code == 2 and "409" in r.stderr and "failed" in r.stderr


# ------------------------------------------------------------------------------------ diagnoses on the jobs page
def test_jobs_page_lists_the_owners_diagnoses(service):
    """Each finished FE job's diagnosis, in the state GET /jobs/{id}/diagnosis gives, the finished one linked to
    its diagnosis report; jobs without a diagnosis, and another user's diagnoses, are not listed."""
    from svc_helpers import done_fe_job, show_running, store_diagnosis

    settings, http = service.settings, service.http
    done, failed, running, plain = (done_fe_job(settings, owner="alice") for _ in range(4))
    bobs = done_fe_job(settings, owner="bob")
    for jid in (done, bobs):
        store_diagnosis(
            settings,
            jid,
            report={"verdict": "missing physics: leak <named>", "n_simulations": 1234, "wall_s": 125.0},
            png=b"\x89PNG\r\n\x1a\n",
        )
    store_diagnosis(settings, failed, "failed", error="RuntimeError: the cluster went <away>")
    in_flight = store_diagnosis(settings, running, "running")  # a diagnosis in flight, as the manager keeps it
    with show_running(
        service.server.config.app.state.manager,
        in_flight,
        {"stage": "refit", "entry": "leak", "step": 2, "steps": 6, "simulations": 480, "elapsed_s": 75.0},
    ):
        page = http.get("/", headers=auth("alice")).text
    diag = page[page.index("<h2>Diagnoses</h2>") :]
    assert _ids(page) == {done, failed, running, plain} and bobs not in page
    assert _ids(diag) == {done, failed, running}  # no row for the undiagnosed job
    assert "missing physics: leak &lt;named&gt;" in diag and "1,234" in diag and "2 min 05 s" in diag
    assert "the cluster went &lt;away&gt;" in diag and "refit leak (2 of 6)" in diag and "480" in diag
    _no_external_host(page)
    links = re.findall(r"href='(/jobs/[^']+/diagnosis/report\?[^']+)'", page)
    assert len(links) == 1 and done in links[0]  # the finished diagnosis only
    r = httpx.get(service.url + links[0].replace("&amp;", "&"), timeout=60)  # no bearer header: the signed link
    assert r.status_code == 200 and "missing physics: leak" in r.text.lower()
    by_link = httpx.get(service.url + http.post("/page-link", headers=auth("alice")).json()["url"], timeout=60)
    assert "<h2>Diagnoses</h2>" in by_link.text and _ids(by_link.text) == _ids(page)
    assert "<h2>Diagnoses</h2>" not in http.get("/", headers=auth("carol")).text
