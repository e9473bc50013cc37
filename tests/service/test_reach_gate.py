"""The reach check at the edges: `vfinfer infer` refuses a recording outside the model's reach (exit 2, one
`error:` line with the numbers) unless --force-reach, `vfinfer reach` builds and caches an ensemble, and
POST /jobs answers 422 with the numbers (or, with force_reach, accepts the job with a warning in its status).
No FE simulation runs here: the shipped ensemble answers, and builds use a stand-in simulator."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from fastapi.testclient import TestClient
from svc_helpers import TOKENS, auth
from typer.testing import CliRunner

from service.cli import app as cli_app

FPS = 4000.0
CHEAP = ["--mesh", "coarse", "--dt", "1e-4", "--sampler", "is", "--n", "4"]
FIXED = ["--fix", "x0=8.4", "--fix", "rho=1051", "--fix", "eta=3.079", "--fix", "E_lig=1.808"]


def sine(f0=200.0, seconds=0.25, peak=20.0):
    t = np.arange(int(seconds * FPS)) / FPS
    return t, peak * 0.5 * (1 - np.cos(2 * np.pi * f0 * t))


@pytest.fixture
def gaw_200(tmp_path):
    from vfvideo.io import write_gaw_csv

    t, a = sine()
    return write_gaw_csv(tmp_path / "sine200.csv", t, a, FPS)


@pytest.fixture(autouse=True)
def empty_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("VFINFER_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path / "cache" / "reach"


def _lines(out: str) -> list[str]:
    return [ln for ln in out.splitlines() if ln.strip()]


@pytest.mark.parametrize("extra", [[], FIXED], ids=["table2", "issue-fixes"])
def test_infer_outside_the_reach_exits_2_with_one_line(tmp_path, gaw_200, extra):
    """A 200-Hz sine against the shipped coarse/dt=1e-4 ensemble (and, with four parameters fixed, against it as
    the ensemble of a wider prior): one error line with the recording's f0 and the reach, nothing run."""
    r = CliRunner().invoke(
        cli_app, ["infer", str(gaw_200), *CHEAP, *extra, "--out", str(tmp_path / "o")], env={"COLUMNS": "80"}
    )
    assert r.exit_code == 2, r.output
    lines = _lines(r.output)
    assert len(lines) == 1 and lines[0].startswith("error: recording outside this model's reach"), r.output
    assert "recording f0 200 Hz; this model and prior reach " in lines[0] and "Hz (5-95 %), at most" in lines[0]
    assert "--force-reach" in lines[0] and "--prior E_body" in lines[0]
    assert ("wider prior" in lines[0]) == bool(extra)
    assert not (tmp_path / "o").exists()


def test_infer_with_force_reach_warns_and_fits(tmp_path, gaw_200, monkeypatch):
    """--force-reach: the same recording is fitted (the fit is a stand-in here) after one warning line."""
    import service.cli as cli

    seen = {}

    def fake_run_local(spec, out, workers, job_id="local"):
        seen["spec"] = spec
        return {
            "table": [
                {"name": "E_body", "unit": "kPa", "mean": 14.98, "sd": 0.02, "pct": 0.1, "q05": 14.95, "q95": 15.0}
            ],
            "method": "importance",
            "n_simulations": 4,
            "n_failed": 0,
            "ess": 3.0,
            "warnings": ["AT PRIOR BOUND: E_body stand-in"],
        }

    monkeypatch.setattr(cli, "run_local", fake_run_local)
    r = CliRunner().invoke(
        cli_app, ["infer", str(gaw_200), *CHEAP, "--force-reach", "--out", str(tmp_path / "o")], env={"COLUMNS": "80"}
    )
    assert r.exit_code == 0, r.output
    assert seen["spec"].force_reach is True
    warn = [ln for ln in r.output.splitlines() if "outside this model's reach" in ln]
    assert len(warn) == 1 and warn[0].startswith("warning:") and "--force-reach: fitting anyway" in warn[0]
    assert "AT PRIOR BOUND: E_body" in r.output


def fake_simulate(rows, config, block=32):
    t = np.arange(1200) / config.fps
    return [
        SimpleNamespace(ok=True, fps=config.fps, f0=6.0 * r[0], gaw=10.0 * (1 - np.cos(2 * np.pi * 6.0 * r[0] * t)))
        for r in rows
    ]


def test_reach_command_builds_caches_and_checks(tmp_path, gaw_200, empty_cache, monkeypatch):
    import vfcore.batch

    monkeypatch.setattr(vfcore.batch, "simulate_many", fake_simulate)
    args = ["reach", "--mesh", "coarse", "--dt", "1e-4", "--fix", "E_lig=1.808", "--n", "6"]
    r = CliRunner().invoke(cli_app, args, env={"COLUMNS": "200"})
    assert r.exit_code == 0, r.output
    assert "reach: 6 draws in" in r.output and "| f0 | Hz |" in r.output
    files = list(empty_cache.glob("reach_*.csv"))
    assert len(files) == 1
    # a second call reads the cache instead of simulating, and --check compares a recording
    monkeypatch.setattr(vfcore.batch, "simulate_many", None)
    r = CliRunner().invoke(cli_app, [*args, "--check", str(gaw_200)], env={"COLUMNS": "200"})
    assert r.exit_code == 0, r.output
    assert f"ensemble of 6 draws from {files[0]}" in r.output and "draws in" not in r.output
    assert "outside: recording outside this model's reach: recording f0 200 Hz" in r.output


def test_reach_command_bad_prior_is_one_error_line():
    r = CliRunner().invoke(cli_app, ["reach", "--prior", "E_body=15:9"], env={"COLUMNS": "80"})
    assert r.exit_code == 2 and _lines(r.output)[0].startswith("error:") and len(_lines(r.output)) == 1, r.output


# ------------------------------------------------------------------------------------------ service
class NoCluster:
    """Stands in for the Dask client: jobs accepted here are not run (their runs fail at once)."""


@pytest.fixture
def http(tmp_path):
    from service.main import create_app
    from service.settings import Settings

    settings = Settings(data_dir=tmp_path / "data", users=TOKENS, allow_toy_model=True, max_running_jobs=1)
    with TestClient(create_app(settings, client=NoCluster())) as c:
        yield c


def fe_body(f0=200.0, **kw):
    t, a = sine(f0)
    body = {
        "model": "fe",
        "gaw": {"areas": a.tolist(), "fps": FPS},
        "sampler": {"kind": "is", "n_samples": 1},
        "mesh": "coarse",
        "dt": 1e-4,
        "duration": 0.55,
        "discard": 0.25,
        "sigma_e": 1.0,
        "seed": 0,
    }
    body.update(kw)
    return body


def test_service_422_outside_the_reach(http):
    r = http.post("/jobs", json=fe_body(), headers=auth("alice"))
    assert r.status_code == 422, r.text
    d = r.json()["detail"][0]
    assert d["loc"] == ["body", "gaw"] and d["reach"]["verdict"] == "outside"
    assert "recording f0 200 Hz; this model and prior reach" in d["msg"] and "(5-95 %)" in d["msg"]
    assert "force_reach: true" in d["msg"]
    assert d["reach"]["measures"]["f0_hz"]["max"] < 200.0
    assert http.get("/jobs", headers=auth("alice")).json() == []


def test_service_force_reach_accepts_with_a_warning_in_the_status(http):
    r = http.post("/jobs", json=fe_body(force_reach=True), headers=auth("alice"))
    assert r.status_code == 202, r.text
    ws = r.json()["warnings"]
    assert len(ws) == 1 and ws[0].startswith("REACH: recording outside") and "force_reach" in ws[0]
    st = http.get(f"/jobs/{r.json()['id']}", headers=auth("alice")).json()
    assert st["warnings"] == ws and st["stats"]["reach"]["verdict"] == "outside"


def test_service_without_an_ensemble_warns_and_says_how_to_build_one(http):
    r = http.post("/jobs", json=fe_body(mesh="medium"), headers=auth("alice"))
    assert r.status_code == 202, r.text
    ws = r.json()["warnings"]
    assert len(ws) == 1 and "reach was not checked" in ws[0] and "vfinfer reach --mesh medium --dt 0.0001" in ws[0]


def test_layer_job_hint_builds_the_ensemble_it_needs(tmp_path, empty_cache, monkeypatch):
    """A job with the compliant contact layer has no shipped ensemble (the key includes the contact law); the
    command its warning prints builds one that the same job then finds as its own."""
    import shlex

    import vfcore.batch
    from vfcore.inference import reach as rc
    from worker.jobspec import JobSpec

    spec = JobSpec.model_validate(fe_body(contact="layer", contact_layer_mm=0.05))
    cfg, prior = spec.sim_config(), spec.to_prior()
    assert rc.find_ensemble(cfg, prior) == (None, False)
    hint = rc.build_hint(cfg, prior)
    cmd = hint.split("`")[1]
    assert "--contact layer --contact-layer-mm 0.05" in cmd
    monkeypatch.setattr(vfcore.batch, "simulate_many", fake_simulate)
    r = CliRunner().invoke(cli_app, [*shlex.split(cmd)[1:], "--n", "6"], env={"COLUMNS": "200"})
    assert r.exit_code == 0, r.output
    ens, exact = rc.find_ensemble(cfg, prior)
    assert exact and ens.n == 6 and ens.sim_config().contact == "layer"
    # the projection's ensemble for the same mesh and step (shipped or none) is another one
    other = rc.find_ensemble(cfg.replace(contact="projection"), prior)[0]
    assert getattr(other, "key", None) != ens.key


def test_an_element_hint_is_a_command_the_cli_runs(tmp_path, empty_cache, monkeypatch):
    """A library fit with the locking-free element gets a hint with ``--element anp``; `vfinfer reach` takes it
    and builds the ensemble that configuration then finds (the key includes the element)."""
    import shlex

    import vfcore.batch
    from vfcore.inference import reach as rc
    from worker.jobspec import JobSpec

    spec = JobSpec.model_validate(fe_body())
    cfg, prior = spec.sim_config().replace(element="anp"), spec.to_prior()
    assert rc.find_ensemble(cfg, prior) == (None, False)
    cmd = rc.build_hint(cfg, prior).split("`")[1]
    assert "--element anp" in cmd
    monkeypatch.setattr(vfcore.batch, "simulate_many", fake_simulate)
    r = CliRunner().invoke(cli_app, [*shlex.split(cmd)[1:], "--n", "6"], env={"COLUMNS": "200"})
    assert r.exit_code == 0, r.output
    ens, exact = rc.find_ensemble(cfg, prior)
    assert exact and ens.sim_config().element == "anp"
    assert getattr(rc.find_ensemble(cfg.replace(element="p1"), prior)[0], "key", None) != ens.key


def test_infer_builds_a_missing_ensemble_on_first_use_caches_it_and_says_which(
    tmp_path, gaw_200, empty_cache, monkeypatch
):
    """The paper's medium mesh has no shipped ensemble: the first `vfinfer infer` builds one of the prior set (a
    line says so, with its cost and where it goes), the recording is checked against it, and the next run reads
    it from the cache; the coarse default says "shipped"; VFINFER_REACH_BUILD=0 builds nothing. Stand-in
    simulator (vfinfer reach's test), stand-in fit."""
    import service.cli as cli
    import vfcore.batch
    from vfcore.inference import reach as rc
    from vfcore.inference.prior import Prior as PriorBox

    monkeypatch.setattr(
        cli,
        "run_local",
        lambda spec, out, workers, job_id="local": {
            "table": [],
            "method": "importance",
            "n_simulations": 4,
            "n_failed": 0,
            "ess": 3.0,
        },
    )
    monkeypatch.setattr(rc, "DEFAULT_N", 40)
    args = [
        "infer",
        str(gaw_200),
        "--mesh",
        "medium",
        "--fix",
        "x0=8.4",
        "--sampler",
        "is",
        "--n",
        "4",
        "--workers",
        "1",
        "--force-reach",
    ]
    monkeypatch.setenv("VFINFER_REACH_BUILD", "0")
    r = CliRunner().invoke(cli_app, [*args, "--out", str(tmp_path / "o0")], env={"COLUMNS": "200"})
    assert r.exit_code == 0 and "was not checked" in r.output and "building" not in r.output, r.output
    assert not list(empty_cache.glob("reach_*.csv"))

    monkeypatch.setenv("VFINFER_REACH_BUILD", "1")
    monkeypatch.setattr(vfcore.batch, "simulate_many", fake_simulate)
    r = CliRunner().invoke(cli_app, [*args, "--out", str(tmp_path / "o1")], env={"COLUMNS": "200"})
    assert r.exit_code == 0, r.output
    files = list(empty_cache.glob("reach_*.csv"))
    assert len(files) == 1
    assert "building one now: 40 prior draws" in r.output and f"cached in {files[0]}" in r.output
    assert "reach: built now: 40 draws" in r.output
    ens = rc.ReachEnsemble.load(files[0])
    assert ens.sim_config().mesh == "medium" and ens.prior_obj().to_dict() == PriorBox.default().to_dict()
    assert "was not checked: no reach ensemble" not in r.output
    assert "outside this model's reach" in r.output and f"(reach ensemble: built now, {files[0]})" in r.output

    monkeypatch.setattr(rc, "build_ensemble", None)  # the cache answers: nothing is built
    r = CliRunner().invoke(cli_app, [*args, "--out", str(tmp_path / "o2")], env={"COLUMNS": "200"})
    assert r.exit_code == 0 and f"(reach ensemble: cached ensemble of 40 draws, {files[0]})" in r.output, r.output
    assert "building" not in r.output
    r = CliRunner().invoke(
        cli_app, ["infer", str(gaw_200), *CHEAP, "--force-reach", "--out", str(tmp_path / "o3")], env={"COLUMNS": "200"}
    )
    assert r.exit_code == 0 and "(reach ensemble: shipped ensemble of 2000 draws, " in r.output, r.output
