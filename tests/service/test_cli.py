"""The vfinfer CLI against a running service (submit / status / fetch) and locally (infer)."""
from __future__ import annotations

import re

import numpy as np
from typer.testing import CliRunner

from svc_helpers import TOKENS, toy_spec

from service.cli import app


def _gaw_file(tmp_path):
    from vfvideo.io import write_gaw_csv
    areas = np.array(toy_spec()["gaw"]["areas"])
    return write_gaw_csv(tmp_path / "gaw.csv", np.arange(areas.size) / 4000.0, areas, 4000.0)


TOY = ["--model", "toy", "--n", "120", "--duration", "0.35", "--discard", "0.2", "--sigma-e", "10",
       "--prior", "E_cover=450:850", "--prior", "p_sub=700:1300", "--fix", "E_body=12.15", "--fix", "E_lig=1.808",
       "--fix", "rho=1051", "--fix", "eta=3.079", "--fix", "x0=8.4"]


def test_submit_status_fetch(service, tmp_path):
    gaw = _gaw_file(tmp_path)
    env = {"VFINFER_URL": service.url, "VFINFER_TOKEN": TOKENS["carol"], "COLUMNS": "200"}
    r = CliRunner().invoke(app, ["submit", str(gaw), *TOY], env=env)
    assert r.exit_code == 0, r.output
    job_id = re.findall(r"[A-Za-z0-9_-]{32}", r.output)[-1]
    r = CliRunner().invoke(app, ["status", job_id, "--wait"], env=env)
    assert r.exit_code == 0 and "done" in r.output, r.output
    r = CliRunner().invoke(app, ["fetch", job_id, "--out", str(tmp_path / "out")], env=env)
    assert r.exit_code == 0, r.output
    assert "E_cover" in r.output and "% of est." in r.output
    for f in ("posterior.json", "samples.csv", "gaw_fit.png", "corner.png", "contact_pressure.png"):
        assert (tmp_path / "out" / f).stat().st_size > 0
    r = CliRunner().invoke(app, ["status", job_id], env={**env, "VFINFER_TOKEN": TOKENS["alice"]})
    assert r.exit_code == 1 and "404" in r.output


def test_bad_cli_input_names_field(tmp_path):
    gaw = _gaw_file(tmp_path)
    r = CliRunner().invoke(app, ["infer", str(gaw), *TOY, "--prior", "E_cover=900:400"], env={"COLUMNS": "200"})
    assert r.exit_code == 2 and "priors" in r.output


def test_job_ids_are_valid_cli_arguments():
    """A job id must pass the API's pattern and never start with "-" (typer would read it as an
    option). Under the old URL-safe tokens 1 id in 64 did: 2,000 draws would all pass with
    probability (63/64)^2000 ~ 2e-14."""
    from service.deps import JOB_ID_RE
    from service.manager import new_job_id
    ids = {new_job_id() for _ in range(2000)}
    assert len(ids) == 2000
    assert all(JOB_ID_RE.match(j) and not j.startswith("-") for j in ids)
