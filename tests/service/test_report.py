"""The figures and the HTML report of a posterior: deterministic PNGs (the same posterior gives the same bytes),
a pair plot with truth lines, and a report page that reads offline (relative links or embedded images, no
external host) and shows the table with units and intervals."""

from __future__ import annotations

import json

import numpy as np
import pytest
from svc_helpers import toy_spec


@pytest.fixture(scope="module")
def post():
    from toy_model import ToyEvaluator

    from vfcore.inference.smc import smc
    from worker.jobspec import JobSpec

    pb = JobSpec.model_validate(toy_spec(sigma_e=0.5)).to_problem()
    p = smc(ToyEvaluator(pb), pb.prior, n_particles=60, seed=1)
    p.obs_gaw, p.fps = pb.obs_compared, pb.fps
    return p


def test_figures_are_deterministic_pngs(post):
    from worker.figures import fig_contact, fig_corner, fig_gaw_fit

    g = np.asarray(post.resampled_predictive().gaw, dtype=float)
    bands = np.quantile(g, [0.05, 0.5, 0.95], axis=0)
    for make in (
        lambda: fig_gaw_fit(post, bands, 0.5),
        lambda: fig_corner(post, truth={"E_cover": 636.2}),
        lambda: fig_contact(post),
    ):
        a, b = make(), make()
        assert a[:8] == b"\x89PNG\r\n\x1a\n" and a == b


def test_replicate_band_is_wider_than_the_model_band(post):
    from worker.figures import replicate_band

    g = np.asarray(post.resampled_predictive().gaw, dtype=float)
    model = np.quantile(g, [0.05, 0.95], axis=0)
    rep = replicate_band(g, 0.5)
    assert np.all(rep[2] - rep[0] > model[1] - model[0])
    assert abs(np.median(rep[2] - rep[0]) - 2 * 1.645 * 0.5) < 0.3  # ~ the noise's own 90 % width


def test_report_folder_reads_offline(tmp_path, post):
    from service.report import write_report
    from worker.reduce import posterior_summary, samples_csv

    summary = posterior_summary(post)
    csv_bytes, meta = samples_csv(post)
    (tmp_path / "samples.csv").write_bytes(csv_bytes)
    (tmp_path / "samples.json").write_bytes(meta)
    (tmp_path / "gaw_fit.png").write_bytes(b"\x89PNG\r\n\x1a\n")
    (tmp_path / "timings.json").write_text(json.dumps({"wall_s": 12.5, "n_simulations": 60}))
    page = write_report(tmp_path, summary, title="toy <job>").read_text()
    assert "toy &lt;job&gt;" in page  # text is escaped
    assert "src='gaw_fit.png'" in page and "corner.png" not in page  # only what exists
    assert "href='samples.csv'" in page and "href='samples.json'" in page
    assert "http://" not in page and "https://" not in page and "<script" not in page
    assert (
        "E_cover" in page
        and "Pa" in page
        and "90 % interval" in page
        and "wall 12.5 s" in page
        and "n simulations 60" in page
    )
    assert json.loads(meta)["units"] == {"E_cover": "Pa", "p_sub": "Pa"}
    header = csv_bytes.decode().splitlines()[0]
    assert header == "E_cover,p_sub,log_weight,weight,n_resampled"


def test_the_report_says_which_independent_runs_were_pooled(post):
    """A pooled posterior's page lists every run's evidence and marks the one left out."""
    import copy

    from service.report import _diagnostics
    from vfcore.inference.runs import pool_runs
    from worker.reduce import posterior_summary

    a, b, c = copy.deepcopy(post), copy.deepcopy(post), copy.deepcopy(post)
    top = a.info["max_loglik"]
    b.info["max_loglik"], c.info["max_loglik"] = top - 1.0, top - 12.0
    lines = " ".join(t for _, t in _diagnostics(posterior_summary(pool_runs([a, b, c]))))
    assert "3 independent SMC runs, best log-likelihood" in lines and lines.count("(left out)") == 1, lines
    assert f"{top - 12.0:.1f} (left out)" in lines and "more than 3 nats below the best" in lines
    assert "the intervals are not calibrated" in lines
    assert "independent" not in " ".join(t for _, t in _diagnostics(posterior_summary(post)))


@pytest.mark.parametrize("contact, depends_on", [("projection", "mesh and time step"), ("layer", "mesh")])
def test_terminal_and_report_both_label_the_unconverged_contact_peaks(tmp_path, post, capsys, contact, depends_on):
    """The nodal peak pressures depend on the resolution: `vfinfer infer`'s table and the HTML page both say on
    what; the flow, which converges, carries no such label in either."""
    from types import SimpleNamespace

    from service.cli_tables import print_table
    from service.report import write_report
    from worker.reduce import _predictive_summary, posterior_summary

    rng = np.random.default_rng(0)
    pred = SimpleNamespace(
        gaw=None,
        mean_flow=rng.uniform(1e-4, 2e-4, 40),
        max_contact=rng.uniform(1e4, 3e4, 40),
        mean_contact=None,
        contact_impulse=None,
        contact_pressure_in_contact=None,
    )
    summary = posterior_summary(post, _predictive_summary(pred, contact)[0])
    print_table(summary)
    lines = capsys.readouterr().out.splitlines()
    contact_line = next(ln for ln in lines if ln.strip().startswith("max_contact:"))
    flow_line = next(ln for ln in lines if ln.strip().startswith("mean_flow:"))
    assert contact_line.endswith(f"(depends on {depends_on})"), contact_line
    assert "depends on" not in flow_line
    page = write_report(tmp_path, summary).read_text()
    row = next(r for r in page.split("<tr>") if "max contact" in r)
    assert f"(depends on {depends_on})" in row
    assert "depends on" not in next(r for r in page.split("<tr>") if "mean flow" in r)
