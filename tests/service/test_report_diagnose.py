"""The HTML page of a diagnosis, from stored reports (no diagnosis runs here): the verdict with its evidence or
the "no missing physics" verdict, where the mismatch lies, the ranked catalogue entries and the cost, in a
well-formed page that loads nothing from another host and runs no script; the CLI writes it as index.html
and the service serves it to the job's owner (bearer token or a signed link) and to no one else."""

from __future__ import annotations

import copy
import re
from html.parser import HTMLParser

import pytest
from svc_helpers import auth, done_fe_job

#: A report as ``DiagnoseReport.to_dict()`` after ``jsonable`` writes it (strict JSON: None for non-finite).
REPORT = {
    "verdict": "missing physics: leak (dlogZ = 300.00 +- 0.50, residual RMS 80 % lower, removes 90 % of the "
    "localised residual)",
    "winner": "leak",
    "physics": "leak",
    "rivals": [{"physics": "scale", "gap": 2.0, "se": 1.5}],
    "base": {
        "residual_rms": 1.5,
        "log_evidence": -500.0,
        "log_evidence_se": 0.3,
        "dominant_phase": "closed",
        "n_simulations": 100,
        "phase_rms": {"closed": 2.1, "opening": 0.9, "peak": 0.7, "closing": None},
        "concentration": {"closed": 1.9, "opening": 0.6, "peak": 0.4, "closing": None},
        "pvalues": {"min_area_mm2": 0.001, "open_quotient": 0.4},
        "measures": {
            "min_area_mm2": {"observed": 1.5, "predicted": 0.1, "predicted_sd": 0.1},
            "open_quotient": {"observed": 0.6, "predicted": 0.58, "predicted_sd": 0.03},
        },
        "predictive_noise_sd": 0.3,
        "params": {"E_cover": {"mean": 640.0, "sd": 12.0}},
    },
    "screening": {
        "leak": {"score": 40.0, "best_phi": {"leak_mm2": 1.4}, "n_simulations": 0},
        "scale": {"score": 3.0, "best_phi": {"scale": 1.02}, "n_simulations": 0},
        "exposure": {"score": -1.0, "best_phi": {}, "n_simulations": 0},
        "_meta": {"x": 1.0},
    },
    "refits": {
        "leak": {
            "params": {"E_cover": {"mean": 636.0, "sd": 9.0}, "leak_mm2": {"mean": 1.5, "sd": 0.1}},
            "residual_rms": 0.3,
            "rms_improvement": 0.8,
            "pvalues": {"min_area_mm2": 0.5, "open_quotient": 0.45},
            "measures": {"min_area_mm2": {"predicted": 1.45}, "open_quotient": {"predicted": 0.6}},
        },
        "scale": {"params": {"scale": {"mean": 1.01, "sd": 0.01}}, "residual_rms": 1.4, "rms_improvement": 0.07},
    },
    "ranking": [
        {"name": "leak", "delta": 300.0, "delta_se": 0.5, "found": True, "residual_removed": 0.9, "reason": ""},
        {
            "name": "scale",
            "delta": 298.0,
            "delta_se": 1.4,
            "found": False,
            "residual_removed": 0.1,
            "reason": "residual RMS only 7 % lower",
        },
    ],
    "reference": "base",
    "notes": ["sigma_e = 1 mm^2 is <larger> than the recording's noise"],
    "n_simulations": 1234,
    "wall_s": 125.0,
    "cost": {
        "by_stage": {"base fit": {"wall_s": 70.0, "simulations": 800}, "refit": {"wall_s": 55.0, "simulations": 434}}
    },
    "request": {"candidates": ["leak", "scale", "exposure"], "n_particles": 12, "max_refits": None},
}
#: A URL that leaves the page: an absolute or protocol-relative src/href, or a CSS url().
EXTERNAL = re.compile(r"""(?:src|href)\s*=\s*["']?(?:[a-z][a-z0-9+.-]*:)?//|url\(""", re.I)
_VOID = {"meta", "img", "br", "link", "hr", "input"}


class _Structure(HTMLParser):
    """Every element opened is closed, in order (void elements excepted); the tags seen."""

    def __init__(self):
        super().__init__()
        self.stack, self.tags, self.errors = [], [], []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        if tag not in _VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes {self.stack[-1:] or 'nothing'}")
        else:
            self.stack.pop()


def check_page(page: str) -> _Structure:
    assert page.startswith("<!doctype html>")
    p = _Structure()
    p.feed(page)
    p.close()
    assert not p.errors and not p.stack, (p.errors, p.stack)
    assert p.tags[:2] == ["html", "head"] and "body" in p.tags and "h1" in p.tags
    assert not EXTERNAL.search(page), EXTERNAL.search(page)
    assert "http://" not in page and "https://" not in page and "<script" not in page.lower()
    return p


def _entries_rows(page: str) -> list[str]:
    table = page[page.index("Catalogue entries, ranked") :]
    table = table[table.index("<table>") : table.index("</table>")]
    return re.findall(r"<code>(\w+)</code>", table)


def test_named_physics_page():
    from service.report_diagnose import render_diagnosis_report

    page = render_diagnosis_report(
        REPORT, "diagnosis.png", "diagnosis of <x>", {"diagnosis.json": "diagnosis.json"}, {"recording": "leaky.csv"}
    )
    check_page(page)
    assert "diagnosis of &lt;x&gt;" in page  # the title is escaped
    assert "Missing physics: leak" in page and "300.00 ± 0.50" in page and "80 % lower" in page
    assert "90 % of the localised residual" in page and "scale (2.0 ± 1.5 nats below)" in page  # a rival
    assert "<strong>closed</strong> phase" in page and "min area mm2" in page and "<strong>0.001 *</strong>" in page
    assert "leak p" in page  # the named entry's p-values beside the base's
    assert _entries_rows(page) == ["leak", "scale", "exposure"]  # refits by dlogZ, then screened only
    assert "<strong>named</strong>" in page and "not refitted" in page and "residual RMS only 7 % lower" in page
    assert "leak_mm2 = 1.5 ± 0.1" in page and "E_cover = 636" not in page  # extension parameters only
    assert "_meta" not in page
    assert "1,234 simulations" in page and "2 min 05 s" in page and "base fit" in page
    assert "&lt;larger&gt;" in page  # notes escaped
    assert "<img src='diagnosis.png'" in page and "leaky.csv" in page and "n particles" in page
    assert "local comparison" not in page
    # a name given on the local comparison leads with that comparison, the global gain beside it
    d = copy.deepcopy(REPORT)
    d["local"] = {"dlogZ": 5000.0, "se": 1.5}
    page = render_diagnosis_report(d, None, "d", None)
    check_page(page)
    assert (
        "named on the local comparison: dlogZ = 5000.00 ± 1.50 nats against the base model refitted in its "
        "material mode; dlogZ = 300.00 ± 0.50 nats against base"
    ) in page


def test_no_finding_page_and_missing_numbers():
    from service.report_diagnose import render_diagnosis_report

    d = copy.deepcopy(REPORT)
    d.update(
        verdict="no missing physics found",
        winner=None,
        physics=None,
        rivals=[],
        refits={},
        ranking=[],
        cost={},
        notes=[],
    )
    d["base"]["dominant_phase"] = "whole cycle"
    d["base"]["residual_rms"] = None
    del d["base"]["measures"]
    page = render_diagnosis_report(d, None, "d", None)
    check_page(page)
    assert "no missing physics found" in page and "Missing physics:" not in page
    assert "spread over the whole cycle" in page and "<img" not in page
    assert _entries_rows(page) == ["leak", "scale", "exposure"]  # screened only, by score
    assert page.count("not refitted") == 3


def test_no_fit_and_material_pages():
    """'The model does not fit' is a warning with the best partial explanation and no name; 'the fixed
    parameters were wrong' shows the pinned and the freed base fits side by side."""
    from service.report_diagnose import render_diagnosis_report

    d = copy.deepcopy(REPORT)
    d.update(
        verdict="the model does not fit: the best fit (leak) leaves a residual RMS of 4.6 mm² against a noise "
        "of 0.46 mm²; best partial explanation: leak",
        winner=None,
        physics=None,
        fit_check={"fits": False, "ratio": 10.0, "max_ratio": 2.0, "best": "leak"},
    )
    page = render_diagnosis_report(d, None, "d", None)
    check_page(page)
    assert "The model does not fit." in page and "10.0 times" in page and "Missing physics:" not in page
    d = copy.deepcopy(REPORT)
    d.update(
        verdict="the fixed parameters were wrong: freeing eta (held at 3.079) gives dlogZ = 900.00 +- 1.00, "
        "residual RMS 60 % lower; no missing physics found",
        winner=None,
        physics=None,
        fit_check={"fits": True, "ratio": 1.1, "max_ratio": 2.0, "best": "base"},
        material={
            "freed": ["eta"],
            "held_at": {"eta": 3.079},
            "anchor": "rho",
            "delta": 900.0,
            "delta_se": 1.0,
            "rms_gain": 0.6,
            "found": True,
            "reason": "",
            "kept": "free",
            "pinned": {"log_evidence": -1400.0, "log_evidence_se": 0.5, "residual_rms": 2.5},
            "free": {
                "log_evidence": -500.0,
                "log_evidence_se": 0.8,
                "residual_rms": 1.0,
                "params": {"eta": {"mean": 6.4, "sd": 0.3}},
            },
        },
    )
    page = render_diagnosis_report(d, None, "d", None)
    check_page(page)
    assert "The fixed parameters were wrong." in page and "Material first" in page
    assert "eta (held at 3.079)" in page and "6.4" in page and "60 % lower" in page


def test_cli_writes_index_html(tmp_path, monkeypatch):
    """``vfinfer diagnose`` with the pipeline replaced by a stand-in returning the stored report."""
    pytest.importorskip("vfcore.forward", reason="FE forward model not available")
    import numpy as np
    from typer.testing import CliRunner

    import vfcore.diagnose.pipeline as P
    from service.cli import app

    t = np.arange(1600) / 4000.0
    gaw = tmp_path / "g.csv"
    gaw.write_text(
        "time_s,area_mm2\n" + "".join(f"{a:.6f},{8 * max(np.sin(2 * np.pi * 120 * a), 0) + 0.5:.5f}\n" for a in t)
    )
    monkeypatch.setattr(P, "diagnose", lambda problem, **kw: type("R", (), {"to_dict": lambda s: dict(REPORT)})())
    monkeypatch.setattr(P, "plot_diagnosis", lambda rep, pb, path: path.write_bytes(b"\x89PNG\r\n\x1a\nfake"))
    out = tmp_path / "out"
    r = CliRunner().invoke(
        app,
        [
            "diagnose",
            str(gaw),
            "--out",
            str(out),
            "--estimate",
            "E_cover",
            "--workers",
            "1",
            "--no-resume",
            "--mesh",
            "coarse",
            "--dt",
            "1e-4",
            "--duration",
            "0.35",
            "--discard",
            "0.15",
        ],
        env={"COLUMNS": "200"},
    )
    assert r.exit_code == 0, r.output
    page = (out / "index.html").read_text()
    check_page(page)
    assert "Missing physics: leak" in page and "<img src='diagnosis.png'" in page
    assert "g.csv" in page and "E_cover" in page and "4000 frames/s" in page
    assert "href='diagnosis.json'" in page
    assert "index.html" in r.output


def test_service_serves_the_page_to_the_owner(service):
    from svc_helpers import store_diagnosis

    from service.report import PAGE_HEADERS

    jid = done_fe_job(service.settings, owner="alice")
    http = service.http
    url = f"/jobs/{jid}/diagnosis/report"
    assert http.get(url, headers=auth("alice")).status_code == 404  # no diagnosis yet
    assert http.post(url + "-link", headers=auth("alice")).status_code == 404
    store_diagnosis(service.settings, jid, report=REPORT, png=b"\x89PNG\r\n\x1a\nfake")
    r = http.get(url, headers=auth("alice"))
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    assert all(r.headers[k] == v for k, v in PAGE_HEADERS.items())
    check_page(r.text)
    assert "Missing physics: leak" in r.text and "<img src='data:image/png;base64," in r.text and jid in r.text
    assert http.get(url, headers=auth("bob")).status_code == 404  # another user's job
    assert http.get(url).status_code == 401
    assert http.post(url + "-link", headers=auth("bob")).status_code == 404
    link = http.post(url + "-link", headers=auth("alice")).json()["url"]
    assert link.startswith(url + "?")
    r = http.get(link)
    assert r.status_code == 200 and "Missing physics: leak" in r.text
    assert http.get(link.replace("sig=", "sig=A")).status_code == 403  # altered
    assert http.get(link.replace("/diagnosis/report", "/report")).status_code == 403  # another page
