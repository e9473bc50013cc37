"""An unknown area scale on the command line and in the job spec (`vfinfer infer --area-scale LO:HI`,
`--uncalibrated`; JobSpec.area_scale, the REST body): carried into the job, its posterior reported."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError
from svc_helpers import toy_spec
from typer.testing import CliRunner

from service.cli import app
from worker.jobspec import JobSpec

TRUE_K = 1.7
ARGS = [
    "--model",
    "toy",
    "--duration",
    "0.35",
    "--discard",
    "0.2",
    "--noise",
    "marginal",
    "--prior",
    "E_cover=450:850",
    "--fix",
    "p_sub=989.9",
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


def _scaled_gaw_file(tmp_path):
    """The toy model at Table 3 recorded with areas TRUE_K times too large, plus noise."""
    from toy_model import toy_observation

    from vfvideo.io import write_gaw_csv

    a = TRUE_K * np.array(toy_observation()) + 0.3 * np.random.default_rng(3).standard_normal(400)
    return write_gaw_csv(tmp_path / "gaw.csv", np.arange(a.size) / 4000.0, a, 4000.0)


@pytest.mark.parametrize("opts, box", [(["--area-scale", "0.5:3"], (0.5, 3.0)), (["--uncalibrated"], (0.25, 4.0))])
def test_infer_fits_the_area_scale_and_prints_it(tmp_path, monkeypatch, opts, box):
    """The fit is the toy model's importance sampler in this process, reduced by the worker's own code."""
    from toy_model import ToyEvaluator

    import service.cli as cli
    from vfcore.inference import importance_sample
    from worker.reduce import area_scale_of, posterior_summary

    seen = {}

    def fake_run_local(spec, out, workers, job_id="local"):
        pb = spec.to_problem()
        post = importance_sample(ToyEvaluator(pb), pb.prior, 300, seed=1)
        pred = post.resampled_predictive()
        seen["scale"] = scale = area_scale_of(spec, pred)
        seen["spec"], seen["post"], seen["pred"] = spec, post, pred
        summary = posterior_summary(post)
        summary["area_scale"] = scale
        return summary

    monkeypatch.setattr(cli, "run_local", fake_run_local)
    r = CliRunner().invoke(
        app, ["infer", str(_scaled_gaw_file(tmp_path)), *ARGS, *opts, "-o", str(tmp_path / "o")], env={"COLUMNS": "250"}
    )
    assert r.exit_code == 0, r.output
    assert seen["spec"].area_scale == box and seen["spec"].to_problem().area_scale == box
    s = seen["scale"]
    assert s["q05"] <= TRUE_K <= s["q95"] and s["sd"] < 0.05, s
    assert (
        "area scale k (recorded / true area)" in r.output and f"prior uniform on [{box[0]:g}, {box[1]:g}]" in r.output
    )
    # the predictive is what the camera records: scaled, so it fits the recording
    y = seen["spec"].to_problem().obs_compared
    g = np.asarray(seen["pred"].gaw, dtype=float)
    assert np.sqrt(np.mean((g - y) ** 2)) < 1.0


def test_the_job_spec_carries_and_checks_the_area_scale():
    spec = JobSpec.model_validate(toy_spec(area_scale=[0.5, 2.0]))
    assert spec.area_scale == (0.5, 2.0) and JobSpec.from_json(spec.to_json()).area_scale == (0.5, 2.0)
    assert JobSpec.model_validate(toy_spec()).area_scale is None
    for bad in ([2.0, 0.5], [0.0, 1.0], [1.0], [1.0, float("inf")], "1:2"):
        with pytest.raises(ValidationError, match="area_scale"):
            JobSpec.model_validate(toy_spec(area_scale=bad))
