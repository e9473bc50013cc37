"""The command line's conventions: --version and -h, the README's `simulate -o`, a warning when the fold does
not oscillate, negative GAW samples within noise kept as measured (deeper ones refused), output folders that appear whole
(--overwrite to replace one), human times in `status`, and `list` / `cancel` against a running service."""

from __future__ import annotations

import json
import re
from types import SimpleNamespace

import numpy as np
import pytest
from svc_helpers import TOKENS, toy_spec
from typer.testing import CliRunner

from service.cli import app
from service.cli_common import human_duration, human_time

TOY = [
    "--model",
    "toy",
    "--sampler",
    "is",
    "--n",
    "40",
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


def _invoke(args, **env):
    return CliRunner().invoke(app, args, env={"COLUMNS": "200", **env})


def _toy_gaw(path, areas=None):
    from vfvideo.io import write_gaw_csv

    a = np.array(toy_spec()["gaw"]["areas"]) if areas is None else areas
    return write_gaw_csv(path, np.arange(a.size) / 4000.0, a, 4000.0)


def test_version_and_short_help():
    from importlib.metadata import version

    r = _invoke(["--version"])
    assert r.exit_code == 0 and r.stdout.strip() == f"vfinfer {version('vfinfer')}"
    for args in ([], ["infer"], ["status"]):
        short, long = _invoke([*args, "-h"]), _invoke([*args, "--help"])
        assert short.exit_code == long.exit_code == 0 and short.stdout == long.stdout and "Usage" in short.stdout


def test_every_option_says_its_unit_or_meaning():
    """No option of a command is left without help text; the physical ones name their unit."""
    import typer.main

    cmd = typer.main.get_command(app)
    units = {
        "--dt": " s",
        "--duration": " s",
        "--discard": " s",
        "--sigma-e": "mm^2",
        "--fps": "frames/s",
        "--px-per-mm": "mm",
        "--segment-s": " s",
        "--fmax": "Hz",
    }
    for name, sub in cmd.commands.items():
        for p in sub.params:
            if getattr(p, "hidden", False) or not getattr(p, "opts", None) or p.opts[0] in ("--help",):
                continue
            assert getattr(p, "help", None), f"vfinfer {name} {p.opts[0]} has no help"
            for opt, unit in units.items():
                if opt in p.opts:
                    assert unit in p.help, f"vfinfer {name} {opt}: no unit in {p.help!r}"


def test_the_command_lines_choices_are_the_models():
    """The contact laws and elements the options accept are vfcore.config's (spelled twice only to keep vfcore's
    import out of the command line's start), and a value the model lacks is refused."""
    import typer

    from service import cli_options
    from vfcore.config import CONTACTS, ELEMENTS

    assert cli_options.CONTACTS == CONTACTS and cli_options.ELEMENTS == ELEMENTS
    for option, values in ((cli_options.Contact, CONTACTS), (cli_options.Element, ELEMENTS)):
        parse = option.__metadata__[0].parser
        assert [parse(v) for v in values] == list(values)
        with pytest.raises(typer.BadParameter):
            parse("rigid")


def test_simulate_o_writes_the_readme_file(tmp_path):
    """README: `vfinfer simulate -o gaw.csv` (coarse mesh here, for speed)."""
    from vfvideo.io import read_gaw

    out = tmp_path / "gaw.csv"
    r = _invoke(["simulate", "--mesh", "coarse", "-o", str(out)])
    assert r.exit_code == 0, r.output
    g = read_gaw(out)
    assert g.fps == 2000.0 and g.area.size > 100 and str(out) in r.stdout


def test_simulate_warns_when_the_fold_does_not_oscillate(tmp_path, monkeypatch):
    import vfcore.forward as forward

    t = np.arange(600) / 2000.0
    monkeypatch.setattr(
        forward,
        "simulate",
        lambda p, c: SimpleNamespace(ok=True, t=t, gaw=np.full(t.size, 2.1), fps=2000.0, f0=float("nan"), message=""),
    )
    r = _invoke(["simulate", "--param", "p_sub=50", "-o", str(tmp_path / "g.csv")])
    assert r.exit_code == 0, r.output
    assert "nan" not in r.stdout.lower()
    err = r.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("warning: the fold does not oscillate") and "p_sub = 50 Pa" in err[0]


@pytest.fixture
def fake_run(monkeypatch):
    """``run_local`` stand-in: records the spec and writes one file, like a run's products."""
    import service.cli as cli

    seen = []

    def run_local(spec, out, workers, job_id="local"):
        seen.append(spec)
        out.mkdir(parents=True, exist_ok=True)
        (out / "posterior.json").write_text(f"run {len(seen)}")
        return {"table": [], "method": "importance", "n_simulations": 1, "n_failed": 0, "ess": 1.0}

    monkeypatch.setattr(cli, "run_local", run_local)
    return seen


def test_negative_samples_within_the_noise_are_kept_as_measured(tmp_path, fake_run):
    """Noise around a closed glottis goes below zero; the Gaussian likelihood expects it, so the samples reach the
    job unchanged (clipping them would bias every closed phase upwards). A baseline error far below the noise is
    refused by the command and by the service's spec alike."""
    from pydantic import ValidationError

    from worker.jobspec import JobSpec

    clean = np.array(toy_spec()["gaw"]["areas"])
    areas = clean + np.random.default_rng(3).normal(0.0, 0.5, clean.size)
    assert areas.min() < -0.5  # noise sd 0.5 mm^2 around the closed phase
    gaw = _toy_gaw(tmp_path / "neg.csv", areas)
    r = _invoke(["infer", str(gaw), *TOY, "--out", str(tmp_path / "o")])
    assert r.exit_code == 0, r.output
    assert not [ln for ln in r.stderr.splitlines() if "negative" in ln], r.stderr
    got = np.array(fake_run[0].gaw.areas)
    np.testing.assert_allclose(got, areas, rtol=1e-8, atol=1e-9)  # the CSV keeps 9 significant digits
    deep = areas.copy()
    deep[10] = -20.0  # 40 noise sds: a baseline error
    r = _invoke(["infer", str(_toy_gaw(tmp_path / "deep.csv", deep)), *TOY, "--out", str(tmp_path / "o2")])
    assert r.exit_code == 2 and "beyond the recording's noise" in r.stderr and len(fake_run) == 1
    body = {**toy_spec(), "gaw": {**toy_spec()["gaw"], "areas": deep.tolist()}}
    with pytest.raises(ValidationError, match="beyond the recording's noise"):
        JobSpec.model_validate(body)
    assert min(JobSpec.model_validate({**body, "gaw": {**body["gaw"], "areas": areas.tolist()}}).gaw.areas) < -0.5


def test_an_output_folder_is_replaced_only_with_overwrite_and_never_half_written(tmp_path, fake_run, monkeypatch):
    import service.cli as cli

    gaw, out = _toy_gaw(tmp_path / "g.csv"), tmp_path / "o"
    assert _invoke(["infer", str(gaw), *TOY, "-o", str(out)]).exit_code == 0
    assert (out / "posterior.json").read_text() == "run 1"
    r = _invoke(["infer", str(gaw), *TOY, "-o", str(out), "--seed", "3"])
    assert r.exit_code == 2 and r.stderr.startswith("error: --out") and "--overwrite" in r.stderr
    assert len(fake_run) == 1
    r = _invoke(["infer", str(gaw), *TOY, "-o", str(out), "--seed", "3", "--overwrite"])
    assert r.exit_code == 0 and (out / "posterior.json").read_text() == "run 2"

    def dies(spec, out, workers, job_id="local"):
        out.mkdir(parents=True, exist_ok=True)
        (out / "half.txt").write_text("half")
        raise RuntimeError("worker lost")

    monkeypatch.setattr(cli, "run_local", dies)
    r = _invoke(["infer", str(gaw), *TOY, "-o", str(tmp_path / "new")])
    assert r.exit_code == 1 and "Traceback" not in r.output
    assert r.stderr.strip() == (
        "error: internal error: RuntimeError: worker lost (VFINFER_DEBUG=1 shows the traceback)"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.csv", "o"]  # nothing of the failed run


def test_human_times():
    assert human_duration(3.21) == "3.2 s" and human_duration(245) == "4 min 05 s"
    assert human_duration(7380) == "2 h 03 min" and human_duration(None) == "-"
    now = 1_800_000_000.0
    s = human_time(now - 330, now=now)
    assert re.fullmatch(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d[+-]\d\d:\d\d \(5 min 30 s ago\)", s), s


def test_list_status_cancel_on_the_service(service):
    """A slow toy job: `list` shows it, `status` says how long ago it was submitted (no epoch seconds), `cancel`
    cancels it, a second cancel says so, and cancelling a finished job is refused."""
    from svc_helpers import auth, wait_done

    env = {"VFINFER_URL": service.url, "VFINFER_TOKEN": TOKENS["carol"]}
    slow = service.http.post("/jobs", json=toy_spec(n=400, delay=0.05), headers=auth("carol")).json()["id"]
    done = service.http.post("/jobs", json=toy_spec(n=40), headers=auth("carol")).json()["id"]
    r = _invoke(["list"], **env)
    assert r.exit_code == 0 and slow in r.stdout and done in r.stdout and " ago" in r.stdout, r.output
    r = _invoke(["status", slow], **env)
    assert r.exit_code == 0 and " ago)" in r.stdout and "simulations" in r.stdout, r.output
    assert not re.search(r"\b1[5-9]\d{8}(\.\d+)?\b", r.stdout), r.stdout  # no raw epoch times
    r = _invoke(["cancel", slow], **env)
    assert r.exit_code == 0 and "cancel" in r.stdout, r.output
    assert wait_done(service.http, slow, "carol")["state"] == "cancelled"
    r = _invoke(["cancel", slow], **env)
    assert r.exit_code == 0 and "already cancelled" in r.stdout, r.output
    wait_done(service.http, done, "carol")
    r = _invoke(["cancel", done], **env)
    assert r.exit_code == 2 and r.stderr.strip() == f"error: job {done} is already done; nothing to cancel"
    r = _invoke(["list", "--state", "cancelled"], **env)
    assert slow in r.stdout and done not in r.stdout
    r = _invoke(["status", done], **{**env, "VFINFER_TOKEN": TOKENS["alice"]})
    assert r.exit_code == 2 and "404" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    r = _invoke(["list"], **{**env, "VFINFER_TOKEN": "wrong-token"})
    assert r.exit_code == 2 and "401" in r.stderr and len(r.stderr.strip().splitlines()) == 1


DEGENERATE = "DEGENERATE ENSEMBLE (smc): final generation acceptance 0.010, 3 distinct particles of 40"


def test_a_python_warning_is_a_warning_line_in_words_and_the_report_lists_it(tmp_path, monkeypatch):
    """A warning the library raises while a fit runs (the degenerate ensemble of the issue) is printed once as a
    `warning:` line, with no file path, line number or source line, and the fit's products list it."""
    import warnings

    import zarr

    import worker.run as wr
    from vfcore.inference.diagnostics import DegenerateEnsembleWarning

    summary = {"table": [], "method": "smc", "n_simulations": 40, "n_failed": 0, "ess": 3.0, "warnings": []}

    def run_job(client, job_id, store_path, spec, report=None):
        warnings.warn(DEGENERATE, DegenerateEnsembleWarning, stacklevel=2)
        zarr.open_group(str(store_path), mode="a", path="posterior").attrs["summary"] = summary
        return {"wall_s": 0.0}

    monkeypatch.setattr(wr, "run_job", run_job)
    out = tmp_path / "o"
    r = _invoke(["infer", str(_toy_gaw(tmp_path / "g.csv")), *TOY, "--workers", "1", "-o", str(out)])
    assert r.exit_code == 0, r.output
    hits = [ln for ln in r.stderr.splitlines() if "DEGENERATE" in ln]
    assert hits == [f"warning: {DEGENERATE}"], r.stderr
    assert ".py:" not in r.output and "warnings.warn" not in r.output and "DegenerateEnsembleWarning" not in r.output
    assert DEGENERATE in json.loads((out / "posterior.json").read_text())["warnings"]
    assert DEGENERATE in (out / "index.html").read_text()


def test_a_diagnosis_shows_a_python_warning_in_words_and_keeps_it_for_its_report(monkeypatch, capsys):
    import warnings

    import service.cli_diagnose as C
    import vfcore.diagnose.pipeline as P
    from service.api_models import DiagnoseRequest

    class Report:
        def to_dict(self):
            return {}

    def diagnose(problem, *, map, **kw):
        warnings.warn(DEGENERATE, UserWarning, stacklevel=2)
        warnings.warn(DEGENERATE, UserWarning, stacklevel=2)  # the same text twice is one line
        return Report()

    monkeypatch.setattr(P, "diagnose", diagnose)
    d, _ = C.run_local(SimpleNamespace(), DiagnoseRequest(), 1, None, None)
    err = capsys.readouterr().err
    assert d["warnings"] == [DEGENERATE]
    assert [ln for ln in err.splitlines() if "DEGENERATE" in ln] == [f"warning: {DEGENERATE}"] and ".py:" not in err
