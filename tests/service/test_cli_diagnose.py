"""`vfinfer diagnose`: bad input exits 2 and writes nothing; a tiny real run on a GAW with a hidden
constant leak names the leak and removes most of the residual."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from service.cli import app

pytest.importorskip("vfcore.forward", reason="FE forward model not available")

FPS = 4000.0
TINY = ["--mesh", "coarse", "--dt", "1e-4", "--duration", "0.35", "--discard", "0.15", "--no-free-material"]


@pytest.fixture(scope="module")
def leaky_gaw(tmp_path_factory):
    """Table 3 simulation + a 1.5 mm^2 constant leak + N(0, 0.3^2) noise, as a GAW CSV."""
    from vfcore import TABLE3, SimConfig, simulate
    from vfvideo.io import write_gaw_csv

    r = simulate(TABLE3, SimConfig(mesh="coarse", dt=1e-4, duration=0.35, discard=0.15, fps=FPS))
    assert r.ok, r.message
    y = r.gaw + 1.5 + np.random.default_rng(3).normal(0.0, 0.3, r.gaw.size)
    path = tmp_path_factory.mktemp("gaw") / "leaky.csv"
    write_gaw_csv(path, r.t, y, r.fps)
    return path


def _invoke(args):
    return CliRunner().invoke(app, ["diagnose", *args])


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--candidates", "leak,warp_drive"], "warp_drive"),
        (["--estimate", "E_cover,stiffness"], "stiffness"),
        (["--fix", "colour=1"], "colour"),
        (["--fix", "E_cover=600"], "E_cover"),  # both estimated and fixed
    ],
)
def test_bad_names_exit_2_and_write_nothing(tmp_path, leaky_gaw, args, needle):
    out = tmp_path / "out"
    r = _invoke(
        [str(leaky_gaw), "--out", str(out), "--estimate", "E_cover", *TINY, *args]
        if "--estimate" not in args
        else [str(leaky_gaw), "--out", str(out), *TINY, *args]
    )
    assert r.exit_code == 2, r.output
    assert "error" in r.output and needle in r.output
    assert not out.exists()


def test_missing_and_invalid_gaw_exit_2(tmp_path):
    out = tmp_path / "out"
    r = _invoke([str(tmp_path / "nope.csv"), "--fps", "4000", "--out", str(out)])
    assert r.exit_code == 2 and "nope.csv" in r.output, r.output
    flat = tmp_path / "flat.csv"
    flat.write_text("area_mm2\n" + "\n".join(["1.0"] * 400) + "\n")
    r = _invoke([str(flat), "--fps", "4000", "--out", str(out)])
    assert r.exit_code == 2 and "error" in r.output, r.output
    assert not out.exists()


@pytest.mark.slow
def test_tiny_diagnosis_names_the_leak(tmp_path, leaky_gaw):
    out = tmp_path / "out"
    r = _invoke(
        [
            str(leaky_gaw),
            "--out",
            str(out),
            *TINY,
            "--estimate",
            "E_cover",
            "--particles",
            "20",
            "--candidates",
            "leak",
            "--max-refits",
            "1",
            "--workers",
            "1",
            "--seed",
            "0",
            "--no-continuation",
        ]
    )  # the continuation search: tests/vfcore/diagnose/test_diagnose_search.py
    assert r.exit_code == 0, r.output
    d = json.loads((out / "diagnosis.json").read_text())
    assert d["winner"] == "leak", d["verdict"]
    assert "leak" in d["verdict"]
    base, refit = d["base"]["residual_rms"], d["refits"]["leak"]["residual_rms"]
    assert refit <= 0.7 * base, (base, refit)
    assert abs(d["refits"]["leak"]["params"]["leak_mm2"]["mean"] - 1.5) < 0.3
    assert d["n_simulations"] > 0
    assert (out / "diagnosis.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "missing physics: leak" in r.output and "Screening" in r.output
    # the leak shows in the recording's minimum area: the base fit's replicates disagree, the leak's do not
    pb, pl = d["base"]["pvalues"], d["refits"]["leak"]["pvalues"]
    assert pb["min_area_mm2"] < 0.05 <= pl["min_area_mm2"], (pb, pl)
    assert "GAW measures" in r.output and "leak p" in r.output
    # the recording's noise (0.3 mm^2) estimated from it, and the note that sigma_e = 1 is not it
    assert d["base"]["predictive_noise_sd"] == pytest.approx(0.3, rel=0.2)
    assert any("sigma_e = 1 mm^2 is" in n for n in d["notes"]), d["notes"]
    import re

    stages = [m.group(1) for m in re.finditer(r"^\s*\d+:\d\d  (.+?) · [\d,]+ simulations$", r.output, re.M)]
    assert stages[:4] == ["base fit", "regularity check", "screening", "refit 1/1: leak"], stages  # progress lines
    assert stages[-1] == "done"
    assert "time by stage: " in r.output and set(d["cost"]["by_stage"]) >= {"base fit", "screening", "refit"}
    assert not (out / ".resume").exists()  # the resume store (on by default) is gone once written
    rs = d["resume_store"]  # a first attempt: everything simulated, nothing earlier
    assert rs["parts_read"] == 0 and rs["parts_simulated"] > 0 and rs["earlier_attempts"] == 0
    assert d["wall_s"] == rs["this_attempt_wall_s"]


def test_library_cli_service_and_benchmark_share_one_set_of_defaults(monkeypatch):
    """`vfinfer diagnose`, POST /jobs/{id}/diagnose, the benchmark script and the library itself take their
    defaults from vfcore.diagnose.DiagnoseOptions, so the benchmark's rates describe the default use and the
    library runs the same diagnosis as the command line."""
    import inspect
    from pathlib import Path

    from service.api_models import DiagnoseRequest
    from service.cli_diagnose import diagnose_cmd
    from vfcore.diagnose import DiagnoseOptions
    from vfcore.diagnose import defaults as D

    o = DiagnoseOptions()
    sig = inspect.signature(diagnose_cmd).parameters
    req = DiagnoseRequest()
    assert (sig["particles"].default, sig["refit_particles"].default, sig["max_refits"].default) == (
        o.n_particles,
        o.refit_particles,
        o.max_refits,
    )
    from service.cli_diagnose import MODEL_DEFAULTS

    assert (MODEL_DEFAULTS["duration"], MODEL_DEFAULTS["discard"]) == (D.DURATION_S, D.DISCARD_S)
    assert sig["duration"].default is sig["dt"].default is None  # None: the --base fit's, else MODEL_DEFAULTS
    assert sig["continuation"].default == req.continuation == o.continuation
    assert sig["free_material"].default == req.free_material == o.free_material
    assert sig["refit_start"].default == req.refit_start == o.refit_start
    assert DiagnoseRequest(refit_start="base").options().refit_start == "base"
    assert (req.n_particles, req.refit_particles, req.max_refits) == (o.n_particles, o.refit_particles, o.max_refits)
    assert req.options() == o  # a default request is the library's default diagnosis
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2]))  # undone after the test
    from benchmarks import bench_diagnose

    seen = {}
    monkeypatch.setattr(bench_diagnose, "run", lambda a: seen.update(vars(a)))
    bench_diagnose.main(["--cases", "c", "--out", "o"])
    assert (seen["particles"], seen["refit_particles"]) == (o.n_particles, o.refit_particles)
    assert seen["continuation"] == o.continuation
    assert seen["continuation_entries"] == o.continuation_entries
    assert seen["escalate_refits"] == o.escalate_refits
    assert seen["refit_start"] == o.refit_start
    assert seen["max_refits"] == 0  # the script's spelling of "all" (None)


def test_the_command_line_and_the_service_take_the_same_bounds():
    """`vfinfer diagnose`, `vfinfer diagnosis --start` and POST /jobs/{id}/diagnose check one DiagnoseRequest:
    a setting one refuses the others refuse, naming the option on the command line; the most refits that
    can be asked for are the catalogue's observation-level entries."""
    from pydantic import ValidationError

    from service.api_models import OBSERVATION_ENTRIES, DiagnoseRequest
    from vfcore.diagnose.extensions import CATALOGUE

    assert OBSERVATION_ENTRIES == sum(e.kind == "observation" for e in CATALOGUE.values())
    for opt, bad in (("--particles", "9"), ("--refit-particles", "9"), ("--max-refits", str(OBSERVATION_ENTRIES + 1))):
        r = CliRunner().invoke(app, ["diagnose", "nope.csv", "--out", "o", opt, bad])
        assert r.exit_code == 2 and opt in r.stderr, (opt, r.output)
        r = CliRunner().invoke(app, ["diagnosis", "a" * 32, "--start", opt, bad])
        assert r.exit_code == 2 and opt in r.stderr, (opt, r.output)
    for field, bad in (("n_particles", 9), ("refit_particles", 9), ("max_refits", OBSERVATION_ENTRIES + 1)):
        with pytest.raises(ValidationError):
            DiagnoseRequest(**{field: bad})


def test_an_interrupted_diagnosis_leaves_its_store_and_the_same_command_reads_it_back(tmp_path, leaky_gaw, monkeypatch):
    """The diagnosis is replaced by one that evaluates 3 parts through the command's map and then
    dies: the store keeps them in OUT/.resume, and the same command run again reads all 3 back."""
    from svc_helpers import dying_diagnosis

    import vfcore.diagnose.pipeline as P

    seen = []
    monkeypatch.setattr(P, "diagnose", dying_diagnosis(seen, "killed"))
    out = tmp_path / "out"
    args = [str(leaky_gaw), "--out", str(out), *TINY, "--estimate", "E_cover", "--workers", "1"]
    r = _invoke(args)
    assert r.exit_code == 1 and "killed" in r.output, r.output
    assert len(list((out / ".resume").rglob("*.pkl"))) == 3
    r = _invoke(args)
    assert "resuming" in r.output and (seen[1].hits, seen[1].misses) == (3, 0)
    assert seen[1].earlier_attempts == 1  # the dead attempt's time is on record
    r = _invoke([*args, "--no-resume"])
    assert seen[2] is map  # --no-resume: the plain map, no store


def _base_posterior(problem, model) -> object:
    """A posterior of ``problem``'s recording with predicted GAWs, recorded as simulated with ``model``."""
    from vfcore.inference.posterior import Posterior
    from vfcore.inference.problem import Evaluation

    rng = np.random.default_rng(0)
    obs = np.asarray(problem.obs_compared, dtype=float)
    samples = np.column_stack([rng.uniform(9, 15, 6), rng.uniform(250, 950, 6)])
    post = Posterior(
        names=("E_body", "E_cover"),
        samples=samples,
        log_weights=np.full(6, -np.log(6)),
        resampled=np.arange(6),
        ess=6.0,
        pareto_k=0.1,
        log_evidence=-1.0,
        log_evidence_se=0.1,
        n_simulations=6,
        method="smc",
        obs_gaw=obs,
        fps=problem.fps,
        model=model,
    )
    post.predictive = Evaluation(
        loglik=np.zeros(6),
        ok=np.ones(6, bool),
        gaw=np.tile(obs, (6, 1)).astype(np.float32),
        mean_flow=np.ones(6),
        mean_contact=np.ones(6),
        max_contact=np.ones(6),
    )
    post.predictive_index = np.arange(6)
    return post


def test_a_base_fitted_with_another_model_is_refused(tmp_path, leaky_gaw):
    """--base must be the model the diagnosis simulates: a fit at another step than the one given is refused
    with one line naming the option and both values; the same model is taken; a file that does not record its
    model (written before it was recorded) is taken as before."""
    from service.cli_diagnose import build_problem, load_base
    from vfcore.inference.posterior import Posterior
    from vfcore.inference.problem import model_record

    problem = build_problem(leaky_gaw, None, "E_body,E_cover", None, "coarse", 1e-4, 0.35, 0.15, 1.0)
    other = problem.config.replace(dt=5e-5, contact="layer")
    _base_posterior(problem, json.loads(json.dumps(other.as_dict()))).to_netcdf(tmp_path / "other.nc")
    out = tmp_path / "out"
    r = _invoke(
        [str(leaky_gaw), "--out", str(out), "--estimate", "E_body,E_cover", *TINY, "--base", str(tmp_path / "other.nc")]
    )
    assert r.exit_code == 2, r.output
    line = " ".join(r.output.split())
    assert "--dt 5e-05" in line and "--dt 0.0001" in line and "leave --dt out" in line, line
    assert "--contact" not in line  # not given: the fit's own law is taken
    assert not out.exists()
    _base_posterior(problem, model_record(problem)).to_netcdf(tmp_path / "same.nc")
    got = load_base(tmp_path / "same.nc", problem)
    assert got.model == model_record(problem) and not problem.config.differences(got.model)
    _base_posterior(problem, None).to_netcdf(tmp_path / "unrecorded.nc")
    assert Posterior.from_netcdf(tmp_path / "unrecorded.nc").model is None
    assert load_base(tmp_path / "unrecorded.nc", problem).names == ("E_body", "E_cover")


def test_a_base_fit_lends_its_model_to_the_settings_not_given(tmp_path, leaky_gaw, monkeypatch):
    """Without --dt, --mesh, --contact ... the diagnosis simulates the --base fit's recorded model (a fit of
    'vfinfer infer' steps at 5e-5 s, a diagnosis by default at 1e-4 s) and says which settings it took; what the
    command line gives still wins, and a clash is refused (previous test)."""
    import service.cli_diagnose as C
    from service.cli_diagnose import build_problem

    problem = build_problem(leaky_gaw, None, "E_body,E_cover", None, "coarse", 1e-4, 0.35, 0.15, 1.0)
    fit = problem.config.replace(dt=5e-5, contact="layer", contact_layer_mm=0.2)
    _base_posterior(problem, json.loads(json.dumps(fit.as_dict()))).to_netcdf(tmp_path / "fit.nc")
    seen = []

    def stop(problem, req, workers, store, base_post):
        seen.append((problem, base_post))
        raise C.fail("stopped before simulating", code=1)

    monkeypatch.setattr(C, "run_local", stop)
    args = [
        str(leaky_gaw),
        "--out",
        str(tmp_path / "out"),
        "--estimate",
        "E_body,E_cover",
        "--duration",
        "0.35",
        "--discard",
        "0.15",
        "--no-free-material",
        "--base",
        str(tmp_path / "fit.nc"),
    ]
    r = _invoke(args)
    assert r.exit_code == 1 and "stopped before simulating" in r.output, r.output
    cfg = seen[0][0].config
    assert (cfg.dt, cfg.contact, cfg.contact_layer_mm, cfg.mesh) == (5e-5, "layer", 0.2, "coarse")
    assert not cfg.differences(seen[0][1].model)
    line = " ".join(r.output.split())
    assert "simulating with the fit's --dt 5e-05, --contact layer, --contact-layer-mm 0.2" in line, line
    r = _invoke([*args, "--contact-layer-mm", "0.3"])
    assert r.exit_code == 2 and "--contact-layer-mm 0.2" in " ".join(r.output.split()), r.output
    r = _invoke([str(leaky_gaw), "--out", str(tmp_path / "out"), "--estimate", "E_body,E_cover", *TINY])
    assert seen[-1][0].config.dt == 1e-4 and seen[-1][0].config.contact == "projection"  # no --base: defaults


def test_the_expected_cost_is_announced_before_the_diagnosis_runs(tmp_path, leaky_gaw, monkeypatch):
    """Both outcomes' simulations and minutes are printed before any fit starts; a candidate subset
    announces fewer catalogue simulations than the whole catalogue."""
    import service.cli_diagnose as C
    from vfcore.diagnose.expected import CATALOGUE_SIMULATIONS, FLOOR_SIMULATIONS

    def stop(problem, req, workers, store, base_post):
        raise C.fail("stopped before simulating", code=1)

    monkeypatch.setattr(C, "run_local", stop)
    args = [str(leaky_gaw), "--out", str(tmp_path / "out"), "--estimate", "E_body,E_cover", *TINY]
    r = CliRunner().invoke(app, ["diagnose", *args], env={"COLUMNS": "250"})
    assert r.exit_code == 1 and "stopped before simulating" in r.output, r.output
    text = " ".join(r.output.split())
    assert text.index("expected cost") < text.index("stopped before simulating")
    assert f"{FLOOR_SIMULATIONS[0]:,}-{FLOOR_SIMULATIONS[1]:,} simulations" in text, text
    assert f"{CATALOGUE_SIMULATIONS[0]:,}-{CATALOGUE_SIMULATIONS[1]:,} simulations" in text, text
    r = CliRunner().invoke(app, ["diagnose", *args, "--candidates", "leak"], env={"COLUMNS": "250"})
    text = " ".join(r.output.split())
    assert f"{CATALOGUE_SIMULATIONS[1]:,} simulations" not in text and "1 of" in text, text
    # E_lig, p_sub and eta held at Table 3 and freed after a pinned fit: two base fits
    pinned = [a for a in args if a != "--no-free-material"]
    r = CliRunner().invoke(app, ["diagnose", *pinned], env={"COLUMNS": "250"})
    text = " ".join(r.output.split())
    assert f"{2 * FLOOR_SIMULATIONS[1]:,} simulations" in text and "a pinned base fit" in text, text
