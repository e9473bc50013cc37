"""The vfinfer CLI against a running service (submit / status / fetch) and locally (infer)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from svc_helpers import TOKENS, toy_spec
from typer.testing import CliRunner

from service.cli import app


def _gaw_file(tmp_path):
    from vfvideo.io import write_gaw_csv

    areas = np.array(toy_spec()["gaw"]["areas"])
    return write_gaw_csv(tmp_path / "gaw.csv", np.arange(areas.size) / 4000.0, areas, 4000.0)


TOY = [
    "--model",
    "toy",
    "--sampler",
    "is",
    "--n",
    "120",
    "--duration",
    "0.35",
    "--discard",
    "0.2",
    "--sigma-e",
    "10",
    "--prior",
    "E_cover=450:850",
    "--prior",
    "p_sub=700:1300",
    "--fix",
    "E_body=12.15",
    "--fix",
    "E_lig=1.808",
    "--fix",
    "rho=1051",
    "--fix",
    "eta=3.079",
    "--fix",
    "x0=8.4",
]


def test_submit_status_fetch(service, tmp_path):
    gaw = _gaw_file(tmp_path)
    env = {"VFINFER_URL": service.url, "VFINFER_TOKEN": TOKENS["carol"], "COLUMNS": "200"}
    r = CliRunner().invoke(app, ["submit", str(gaw), *TOY], env=env)
    assert r.exit_code == 0, r.output
    job_id = re.findall(r"[A-Za-z0-9_-]{32}", r.output)[-1]
    assert r.stdout.strip().splitlines()[-1] == job_id and "expected" not in r.stdout  # the id ends stdout
    assert "expected: 120 simulations" in r.stderr  # importance sampling: exactly its draws
    r = CliRunner().invoke(app, ["status", job_id, "--wait"], env=env)
    assert r.exit_code == 0 and "done" in r.output, r.output
    r = CliRunner().invoke(app, ["fetch", job_id, "--out", str(tmp_path / "out")], env=env)
    assert r.exit_code == 0, r.output
    assert "E_cover" in r.output and "% of est." in r.output
    for f in (
        "posterior.json",
        "samples.csv",
        "samples.json",
        "posterior.nc",
        "gaw_fit.png",
        "corner.png",
        "contact_pressure.png",
        "index.html",
    ):
        assert (tmp_path / "out" / f).stat().st_size > 0
    page = (tmp_path / "out" / "index.html").read_text()
    for f in ("gaw_fit.png", "corner.png", "contact_pressure.png", "samples.csv", "posterior.nc"):
        assert f"'{f}'" in page  # linked relatively: the folder reads offline
    assert "http://" not in page and "https://" not in page
    r = CliRunner().invoke(app, ["status", job_id], env={**env, "VFINFER_TOKEN": TOKENS["alice"]})
    assert r.exit_code == 2 and "404" in r.output


def test_bad_cli_input_names_field(tmp_path):
    gaw = _gaw_file(tmp_path)
    r = CliRunner().invoke(app, ["infer", str(gaw), *TOY, "--prior", "E_cover=900:400"], env={"COLUMNS": "200"})
    assert r.exit_code == 2 and "--prior E_cover" in r.output


@pytest.mark.parametrize(
    "bad",
    [
        "p_sub",
        "p_sub=1000",
        "p_sub=abc:50",
        "p_sub=1000:0",
        "p_sub=1000:-5",
        "p_sub=1000:nan",
        "p_sub=inf:5",
        "p_subglottal=1000:50",
        "rho=1051:10",
    ],
)
def test_bad_measure_is_one_error_line(tmp_path, bad):
    """--measure NAME=MEAN:SD: a malformed, non-finite, non-positive-sd, unknown or fixed (rho, in TOY)
    measurement exits 2 with one 'error:' line and no traceback, before anything runs."""
    gaw = _gaw_file(tmp_path)
    r = CliRunner().invoke(
        app, ["infer", str(gaw), *TOY, "--measure", bad, "--out", str(tmp_path / "o")], env={"COLUMNS": "300"}
    )
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and "measure" in lines[0], r.output
    assert not (tmp_path / "o").exists()


def test_infer_defaults_to_smc_and_prints_what_the_data_determined(tmp_path, monkeypatch):
    """`vfinfer infer` builds an SMC job unless told otherwise, carries --measure into the job, and after
    the fit prints the identifiability table stored with the posterior (the fit itself is a stand-in
    here: the toy model's importance sampler in this process, reduced by the worker's own code)."""
    from toy_model import ToyEvaluator

    import service.cli as cli
    from vfcore.inference import importance_sample
    from worker.reduce import identifiability_of, posterior_summary

    seen = {}

    def fake_run_local(spec, out, workers, job_id="local"):
        seen["spec"] = spec
        pb = spec.to_problem()
        post = importance_sample(ToyEvaluator(pb), pb.prior, 400, seed=1)
        summary = posterior_summary(post)
        summary["identifiability"] = identifiability_of(spec, post)
        return summary

    monkeypatch.setattr(cli, "run_local", fake_run_local)
    gaw = _gaw_file(tmp_path)
    args = [a for a in TOY if a not in ("--sampler", "is")]
    r = CliRunner().invoke(
        app, ["infer", str(gaw), *args, "--measure", "p_sub=1000:50", "-o", str(tmp_path / "o")], env={"COLUMNS": "250"}
    )
    assert r.exit_code == 0, r.output
    spec = seen["spec"]
    assert spec.sampler.kind == "smc" and spec.measurements == {"p_sub": (1000.0, 50.0)}
    for text in (
        "What the data determined",
        "sd / prior sd",
        "E_cover/p_sub",
        "common scale of E_cover, p_sub",
        "measured p_sub = 1000 +- 50 Pa",
    ):
        assert text in r.output, r.output
    # the cost is announced before the run: the measured SMC range for this many particles
    n = spec.sampler.n_particles
    assert f"expected cost: {20 * n:,}-{90 * n:,} simulations" in r.output, r.output
    # independent runs: carried into the job, and the cost multiplied
    r = CliRunner().invoke(
        app, ["infer", str(gaw), *args, "--runs", "3", "-o", str(tmp_path / "o3")], env={"COLUMNS": "250"}
    )
    assert r.exit_code == 0 and seen["spec"].sampler.runs == 3, r.output
    assert f"expected cost: {60 * n:,}-{270 * n:,} simulations" in r.output and "for 3 independent runs" in r.output


def test_job_ids_are_valid_cli_arguments():
    """A job id must pass the API's pattern and never start with "-" (typer would read it as an
    option). With URL-safe tokens 1 id in 64 would: 2,000 draws would all pass with
    probability (63/64)^2000 ~ 2e-14."""
    from service.deps import JOB_ID_RE
    from service.manager import new_job_id

    ids = {new_job_id() for _ in range(2000)}
    assert len(ids) == 2000
    assert all(JOB_ID_RE.match(j) and not j.startswith("-") for j in ids)


def test_diagnosis_on_the_service_start_follow_fetch(service, tmp_path, monkeypatch):
    """``vfinfer diagnosis JOB --start --wait --out DIR`` posts the settings given, prints each new
    stage while it runs, and writes and prints the finished report (the diagnosis itself is a
    stand-in: the real one is tested in test_diagnose_endpoint.py); misuse exits 2, another user's
    job and cancelling a finished diagnosis exit 1 with the service's answer."""
    import json
    import threading

    from svc_helpers import done_fe_job

    import service.diagnosis as D
    import vfcore.diagnose.pipeline as P

    jid = done_fe_job(service.settings, owner="carol")
    report = {
        "verdict": "missing physics: leak",
        "winner": "leak",
        "physics": "leak",
        "rivals": [],
        "base": {
            "residual_rms": 1.5,
            "log_evidence": -500.0,
            "log_evidence_se": 0.3,
            "dominant_phase": "closed",
            "n_simulations": 100,
        },
        "screening": {"leak": {"score": 40.0, "best_phi": {"leak_mm2": 1.4}, "n_simulations": 0}},
        "refits": {
            "leak": {"params": {"leak_mm2": {"mean": 1.5, "sd": 0.1}}, "residual_rms": 0.3, "rms_improvement": 0.8}
        },
        "ranking": [{"name": "leak", "delta": 300.0, "delta_se": 0.5, "found": True}],
        "reference": "base",
        "notes": [],
        "n_simulations": 500,
        "wall_s": 12.0,
        "cost": {"by_stage": {"base fit": {"wall_s": 7.0}, "refit": {"wall_s": 5.0}}},
    }
    seen, go = {}, threading.Event()

    def stand_in(problem, *, map, progress, **kw):
        seen.update(kw)
        progress({"stage": "base fit", "entry": None, "step": None, "steps": None, "simulations": 0, "elapsed_s": 0.0})
        go.wait(2.5)  # long enough for the first poll to see it running
        progress({"stage": "refit", "entry": "leak", "step": 1, "steps": 1, "simulations": 40, "elapsed_s": 2.6})
        go.wait(2.5)
        return type("Report", (), {"to_dict": lambda self: dict(report)})()

    monkeypatch.setattr(P, "diagnose", stand_in)
    monkeypatch.setattr(D, "plot", lambda rep, pb, path: path.write_bytes(b"\x89PNG\r\n\x1a\nfake"))
    env = {"VFINFER_URL": service.url, "VFINFER_TOKEN": TOKENS["carol"], "COLUMNS": "200"}
    out = tmp_path / "diag"
    r = CliRunner().invoke(
        app,
        [
            "diagnosis",
            jid,
            "--start",
            "--candidates",
            "leak,scale",
            "--particles",
            "12",
            "--no-continuation",
            "--wait",
            "--out",
            str(out),
        ],
        env=env,
    )
    assert r.exit_code == 0, r.output
    assert seen["candidates"] == ["leak", "scale"] and seen["n_particles"] == 12 and seen["continuation"] is False
    assert re.search(r"0:0\d  base fit · 0 simulations", r.output) and "refit 1/1: leak · 40 simulations" in r.output
    # the service's announcement: no stored posterior and parameters held at Table 3, so two base fits, of
    # 12 particles where the ranges were measured with the default's
    from vfcore.diagnose.expected import FLOOR_SIMULATIONS
    from vfcore.diagnose.options import DiagnoseOptions

    text = " ".join(r.output.split())
    lo, hi = (round(2 * f * 12 / DiagnoseOptions().n_particles) for f in FLOOR_SIMULATIONS)
    assert f"(it stops there): {lo:,}-{hi:,} simulations if it goes on" in text, text
    assert "n_particles 12" in text and "a pinned base fit before the freed one" in text
    assert text.index("expected cost") < text.index("base fit · 0 simulations")
    assert "diagnosis done" in r.output and "missing physics: leak" in r.output and "time by stage" in r.output
    assert json.loads((out / "diagnosis.json").read_text())["winner"] == "leak"
    assert (out / "diagnosis.png").read_bytes().startswith(b"\x89PNG")
    page = (out / "index.html").read_text()  # the offline report, figure linked relatively
    assert "leak" in page and "src='diagnosis.png'" in page and "http" not in page.split("<body")[1]
    r = CliRunner().invoke(app, ["diagnosis", jid, "--cancel"], env=env)
    assert r.exit_code == 2 and "409" in r.output, r.output  # nothing running
    r = CliRunner().invoke(app, ["diagnosis", jid, "--particles", "12"], env=env)
    assert r.exit_code == 2 and "--start" in r.output
    r = CliRunner().invoke(app, ["diagnosis", jid], env={**env, "VFINFER_TOKEN": TOKENS["alice"]})
    assert r.exit_code == 2 and "404" in r.output


def test_serve_holds_its_port_before_the_app_starts(monkeypatch):
    """``serve`` binds and listens before the app's startup (which starts a LocalCluster binding random ports), and
    uvicorn serves on that very socket: nothing started in between can take the port."""
    import socket

    import uvicorn

    import service.main as main

    seen = {}
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]

    def create_app(settings):
        with socket.socket() as s:  # what a LocalCluster binding the same port would meet
            seen["bind_refused"] = s.connect_ex(("127.0.0.1", port)) == 0
        return object()

    class Server:
        def __init__(self, config):
            pass

        def run(self, sockets):
            seen["served_on"] = [s.getsockname()[1] for s in sockets]

    monkeypatch.setattr(main, "create_app", create_app)
    monkeypatch.setattr(uvicorn, "Server", Server)
    monkeypatch.setattr(uvicorn, "run", lambda *a, **k: seen.setdefault("bound_by_uvicorn", True))
    r = CliRunner().invoke(app, ["serve", "--port", str(port)], env={"VFINFER_TOKENS": "user:a-long-token"})
    assert r.exit_code == 0, r.output
    assert seen == {"bind_refused": True, "served_on": [port]}


def test_serve_on_port_0_binds_one_the_system_picks_and_names_it(monkeypatch):
    """``--port 0``: the port is bound before the app starts and named on the ``listening on`` line, so a caller
    (the service tests) never hands over a port that something else may take first."""
    import re
    import socket

    import uvicorn

    import service.main as main

    seen = {}

    def create_app(settings):
        return object()

    class Server:
        def __init__(self, config):
            pass

        def run(self, sockets):
            port = sockets[0].getsockname()[1]
            with socket.socket() as s:  # the socket listens: a client connects
                seen["connects"] = s.connect_ex(("127.0.0.1", port)) == 0
            seen["served_on"] = port

    monkeypatch.setattr(main, "create_app", create_app)
    monkeypatch.setattr(uvicorn, "Server", Server)
    r = CliRunner().invoke(app, ["serve", "--port", "0"], env={"VFINFER_TOKENS": "user:a-long-token"})
    assert r.exit_code == 0, r.output
    named = re.findall(r"^listening on http://127\.0\.0\.1:(\d+)$", r.stderr, re.M)
    assert seen["connects"] and named == [str(seen["served_on"])] and seen["served_on"] != 0, r.stderr


def test_infer_with_stderr_to_a_pipe_prints_plain_progress_lines(tmp_path):
    """`vfinfer infer ... 2> log`: no bar can draw there, so plain progress lines come at the set interval
    (VFINFER_PROGRESS_INTERVAL, 30 s unless set; a fraction of a second here), each with the stage, the
    simulations and the elapsed time, and none of the bar's control characters. A tiny real FE job."""
    import os
    import re
    import subprocess
    import sys

    from vfvideo.io import write_gaw_csv

    t = np.arange(1400) / 4000.0
    gaw = write_gaw_csv(tmp_path / "g.csv", t, 6.0 * np.maximum(np.sin(2 * np.pi * 120.0 * t), 0.0), 4000.0)
    env = {
        **os.environ,
        "VFINFER_PROGRESS_INTERVAL": "0.3",
        "VFINFER_REACH_BUILD": "0",
        "VFINFER_CACHE_DIR": str(tmp_path / "cache"),
        "OMP_NUM_THREADS": "1",
    }
    p = subprocess.run(
        [
            sys.executable,
            "-m",
            "service.cli",
            "infer",
            str(gaw),
            "--mesh",
            "coarse",
            "--dt",
            "1e-4",
            "--duration",
            "0.35",
            "--discard",
            "0.15",
            "--sampler",
            "is",
            "--n",
            "8",
            "--workers",
            "1",
            "--out",
            str(tmp_path / "o"),
        ],
        cwd=Path(__file__).resolve().parents[2],
        env=env,
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert p.returncode == 0, p.stderr
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("progress: ")]
    assert len(lines) >= 2, p.stderr
    pattern = re.compile(r"^progress: [^·]+( · \d+(/\d+)? simulations)?( · ESS [\d.]+)? · elapsed [\d.]+ s")
    assert all(pattern.match(ln) for ln in lines), lines
    elapsed = [float(re.search(r"elapsed ([\d.]+) s", ln).group(1)) for ln in lines]
    assert elapsed == sorted(elapsed) and elapsed[-1] > elapsed[0]  # a clock that moves: not a hang
    assert "\x1b" not in p.stderr and "\r" not in p.stderr
