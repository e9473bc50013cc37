"""Submit -> poll -> fetch through a real uvicorn server; equality with vfcore called directly."""

from __future__ import annotations

import numpy as np
from svc_helpers import auth, toy_spec, wait_done
from toy_model import ToyEvaluator

from worker.jobspec import JobSpec


def _direct_is(spec_dict):
    from vfcore.inference.importance import importance_sample

    spec = JobSpec.model_validate(spec_dict)
    problem = spec.to_problem()
    return importance_sample(ToyEvaluator(problem), problem.prior, spec.sampler.n_samples, spec.seed, chunk_size=37)


def _check_netcdf(blob: bytes, direct) -> None:
    """The NetCDF export is ArviZ InferenceData holding the resampled posterior, the observed GAW and the
    posterior predictive GAW."""
    import tempfile

    import arviz as az

    with tempfile.NamedTemporaryFile(suffix=".nc") as fh:
        fh.write(blob)
        fh.flush()
        idata = az.from_netcdf(fh.name)
        idata.load() if hasattr(idata, "load") else None
        groups = set(idata.groups())
        assert {"posterior", "observed_data", "posterior_predictive"} <= groups, groups
        np.testing.assert_array_equal(idata["posterior"]["E_cover"].values[0], direct.samples[direct.resampled, 0])
        assert idata["observed_data"]["gaw"].size > 0
        assert idata["posterior_predictive"]["gaw"].shape[:2] == (1, direct.resampled.size)


def test_submit_poll_fetch_same_posterior_as_direct(service):
    http = service.http
    spec = toy_spec(n=600, seed=11)
    r = http.post("/jobs", json=spec, headers=auth("alice"))
    assert r.status_code == 202, r.text
    job_id = r.json()["id"]
    assert len(job_id) == 32
    assert r.json()["expected_simulations"] == [600, 600]  # importance sampling: exactly its draws
    st = wait_done(http, job_id, "alice")
    assert st["state"] == "done", st
    assert st["progress"]["simulations_done"] == st["progress"]["simulations_total"] == 600
    assert st["ess"] > 1
    post = http.get(f"/jobs/{job_id}/posterior", headers=auth("alice")).json()
    js = http.get(f"/jobs/{job_id}/samples", params={"format": "json"}, headers=auth("alice")).json()
    direct = _direct_is(spec)
    np.testing.assert_array_equal(np.array(js["samples"]), direct.samples)
    np.testing.assert_array_equal(np.array(js["resampled"]), direct.resampled)
    lw = np.array([-np.inf if v is None else v for v in js["log_weights"]])
    np.testing.assert_array_equal(lw, direct.log_weights)
    assert post["ess"] == direct.ess
    assert [row["mean"] for row in post["table"]] == [float(m) for m in direct.mean]
    assert post["predictive"]["mean_contact"]["mean"] > 0
    ident = post["identifiability"]  # what the data determined, stored with the job
    assert [r["name"] for r in ident["parameters"]] == ["E_cover", "p_sub"]
    assert abs(ident["parameters"][0]["prior_sd"] - 400.0 / 12**0.5) < 1e-9
    csv = http.get(f"/jobs/{job_id}/samples", headers=auth("alice"))
    assert csv.headers["content-type"].startswith("text/csv")
    assert csv.text.splitlines()[0] == "E_cover,p_sub,log_weight,weight,n_resampled"  # plain CSV, no comment line
    rows = list(__import__("csv").DictReader(csv.text.splitlines()))
    assert len(rows) == 600 and sum(int(r["n_resampled"]) for r in rows) == direct.resampled.size
    meta = http.get(f"/jobs/{job_id}/samples", params={"format": "meta"}, headers=auth("alice")).json()
    assert meta["names"] == ["E_cover", "p_sub"] and meta["units"]["p_sub"] == "Pa" and meta["ess"] == direct.ess
    nc = http.get(f"/jobs/{job_id}/samples", params={"format": "netcdf"}, headers=auth("alice"))
    assert nc.status_code == 200 and nc.headers["content-type"] == "application/x-netcdf"
    _check_netcdf(nc.content, direct)
    page = http.get(f"/jobs/{job_id}/report", headers=auth("alice"))
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    assert page.text.count("data:image/png;base64,") == 3 and "90 % interval" in page.text
    assert "http://" not in page.text and "https://" not in page.text  # readable offline
    assert http.get(f"/jobs/{job_id}/report", headers=auth("bob")).status_code == 404
    assert http.get(f"/jobs/{job_id}/report").status_code == 401
    for name in ("gaw_fit", "corner", "contact_pressure"):
        png = http.get(f"/jobs/{job_id}/figures/{name}", headers=auth("alice"))
        assert png.status_code == 200 and png.content[:8] == b"\x89PNG\r\n\x1a\n"
    assert http.get(f"/jobs/{job_id}/figures/..%2Fjobs.sqlite", headers=auth("alice")).status_code in (404, 422)
    lst = http.get("/jobs", headers=auth("alice")).json()
    assert [j["id"] for j in lst] == [job_id]
    assert http.get("/health").json()["status"] == "ok"
    assert http.get("/docs").status_code == 200
    assert "/jobs/{job_id}/posterior" in http.get("/openapi.json").json()["paths"]


def _smc_job(http, spec):
    """Submit ``spec``, wait for it, and return its status, its samples JSON and its problem."""
    job_id = http.post("/jobs", json=spec, headers=auth("bob")).json()["id"]
    st = wait_done(http, job_id, "bob")
    assert st["state"] == "done", st
    js = http.get(f"/jobs/{job_id}/samples", params={"format": "json"}, headers=auth("bob")).json()
    s = JobSpec.model_validate(spec)
    return job_id, st, js, s, s.to_problem()


def test_smc_generation_by_generation_matches_direct(service):
    from vfcore.inference.smc import smc

    http = service.http
    spec = toy_spec(seed=5, sampler={"kind": "smc", "n_particles": 60, "max_moves": 3})
    job_id, st, js, s, pb = _smc_job(http, spec)
    direct = smc(ToyEvaluator(pb), pb.prior, 60, s.seed, **s.sampler.sampler_options())
    np.testing.assert_array_equal(np.array(js["samples"]), direct.samples)
    post = http.get(f"/jobs/{job_id}/posterior", headers=auth("bob")).json()
    assert (
        post["method"] == "smc" and post["n_simulations"] == direct.n_simulations == st["progress"]["simulations_done"]
    )


def test_smc_with_delayed_acceptance_matches_direct(service):
    """sampler.screen: the service alternates screening and full batches in the job's store exactly as
    vfcore's smc(..., screen=...) does in one process."""
    import dataclasses

    from vfcore.inference.smc import smc

    http = service.http
    spec = toy_spec(
        seed=6, sampler={"kind": "smc", "n_particles": 60, "max_moves": 3, "screen": {"mesh": "coarse", "dt": 1e-4}}
    )
    job_id, st, js, s, pb = _smc_job(http, spec)
    cheap = dataclasses.replace(pb, config=pb.config.replace(mesh="coarse", dt=1e-4))
    direct = smc(ToyEvaluator(pb), pb.prior, 60, s.seed, screen=ToyEvaluator(cheap), **s.sampler.sampler_options())
    np.testing.assert_array_equal(np.array(js["samples"]), direct.samples)
    post = http.get(f"/jobs/{job_id}/posterior", headers=auth("bob")).json()
    assert post["n_simulations"] == direct.n_simulations
    # every batch, screening ones included, went through the store
    assert st["progress"]["simulations_done"] == direct.n_simulations + direct.info["n_screened"]


def test_cancel_frees_cluster(service):
    import time

    http = service.http
    job_id = http.post("/jobs", json=toy_spec(n=400, delay=0.02, chunk_size=10), headers=auth("carol")).json()["id"]
    wait_done(http, job_id, "carol", states=("running",))
    r = http.delete(f"/jobs/{job_id}", headers=auth("carol"))
    assert r.status_code == 200 and r.json()["state"] == "cancelled"
    t0 = time.time()
    while any(service.client.processing().values()) and time.time() - t0 < 10:
        time.sleep(0.05)
    assert not any(service.client.processing().values())
    assert not [k for k in service.client.who_has() if job_id in str(k)]
    assert http.get(f"/jobs/{job_id}", headers=auth("carol")).json()["state"] == "cancelled"


def test_compare(service):
    http = service.http
    a = http.post("/jobs", json=toy_spec(n=300, seed=1), headers=auth("alice")).json()["id"]
    b = http.post("/jobs", json=toy_spec(n=300, seed=2), headers=auth("alice")).json()["id"]
    wait_done(http, a, "alice")
    wait_done(http, b, "alice")
    r = http.post("/compare", json={"job_ids": [a, b]}, headers=auth("alice"))
    assert r.status_code == 200, r.text
    tests = r.json()["tests"]
    assert {t["parameter"] for t in tests} == {"E_cover", "p_sub"}
    assert all(0 <= t["p_value"] <= 1 for t in tests)
    assert http.post("/compare", json={"job_ids": [a, b]}, headers=auth("bob")).status_code == 404


def test_smc_independent_runs_match_direct(service):
    """sampler.runs: the service runs the independent runs one after another through the job's store and
    pools them as vfcore's smc(..., runs=K) does in one process."""
    from vfcore.inference.runs import run_seeds
    from vfcore.inference.smc import smc

    http = service.http
    spec = toy_spec(seed=7, sampler={"kind": "smc", "n_particles": 40, "max_moves": 3, "runs": 2})
    job_id, st, js, s, pb = _smc_job(http, spec)
    direct = smc(ToyEvaluator(pb), pb.prior, 40, s.seed, runs=2, **s.sampler.sampler_options())
    np.testing.assert_array_equal(np.array(js["samples"]), direct.samples)
    np.testing.assert_array_equal(np.array(js["resampled"]), direct.resampled)
    post = http.get(f"/jobs/{job_id}/posterior", headers=auth("bob")).json()
    assert post["n_simulations"] == direct.n_simulations == st["progress"]["simulations_done"]
    assert [r["seed"] for r in post["info"]["runs"]] == run_seeds(s.seed, 2)
    assert post["info"]["runs_kept"] == direct.info["runs_kept"]
    assert post["log_evidence"] == direct.log_evidence
