"""The at-bound warning on real FE fits (:ref:`inference`, "The model's reach"): it fires when a recording lies
outside what the model and prior can make, because the fit presses parameters against the box, and it stays
silent on the demo, whose recording the model made. The rule itself is tested on synthetic posteriors in
tests/worker/test_edge_warnings.py; here the whole command runs."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from vfcore import SimConfig, simulate
from vfcore.gawio import write_gaw_csv
from vfcore.params import Params

pytestmark = pytest.mark.slow

#: a human-range fold (:ref:`inference-reach-prior-sets`): f0 near 176 Hz, outside the paper prior's reach
HUMAN = Params(E_body=100.0, E_cover=5000.0, E_lig=15.0, p_sub=1500.0, rho=1050.0, eta=3.0, x0=8.4)
CHEAP = ["--mesh", "coarse", "--dt", "1e-4", "--duration", "0.35", "--discard", "0.15", "--workers", "1", "--seed", "0"]


def _summary(out):
    return json.loads((out / "posterior.json").read_text())


def test_a_recording_outside_the_reach_is_fitted_against_the_bounds_and_says_so(tmp_path):
    import service.cli as cli

    r = simulate(HUMAN, SimConfig(mesh="coarse", dt=1e-4, duration=0.35, discard=0.15))
    assert r.ok and r.f0 > 150.0
    gaw = write_gaw_csv(tmp_path / "human.csv", r.t, r.gaw, r.fps)
    out = tmp_path / "fit"
    res = CliRunner().invoke(
        cli.app,
        [
            "infer",
            str(gaw),
            *CHEAP,
            "--force-reach",
            "--particles",
            "20",
            "--fix",
            "E_lig=1.808",
            "--fix",
            "rho=1051",
            "--fix",
            "eta=3.079",
            "--fix",
            "x0=8.4",
            "--fix",
            "E_cover=636.2",
            "--out",
            str(out),
        ],
        env={"COLUMNS": "200"},
    )
    assert res.exit_code == 0, res.output[-2000:]
    warnings = _summary(out)["warnings"]
    assert any(w.startswith("AT PRIOR BOUND: E_body") and "upper bound 15" in w for w in warnings), warnings
    assert "AT PRIOR BOUND" in res.output


def test_the_demo_fit_gives_no_at_bound_warning(tmp_path, monkeypatch):
    import service.cli as cli

    monkeypatch.setattr(cli, "_corner_with_truth", lambda folder: None)
    out = tmp_path / "demo"
    res = CliRunner().invoke(
        cli.app, ["demo", "--out", str(out), "--particles", "20", "--workers", "1"], env={"COLUMNS": "200"}
    )
    assert res.exit_code == 0, res.output[-2000:]
    warnings = _summary(out)["warnings"]
    assert not any("AT PRIOR BOUND" in w for w in warnings), warnings
