"""End to end through the real finite-element model (coarse mesh, a few hundred simulations):
submit -> poll -> fetch equals vfcore.inference.importance_sample called directly, same seed."""

from __future__ import annotations

import numpy as np
import pytest
from svc_helpers import auth, wait_done

pytest.importorskip("vfcore.forward", reason="FE forward model not available yet")

N = 160


@pytest.fixture(scope="module")
def demo_gaw(tmp_path_factory):
    from vfcore.data import DEMO_GAW, make_demo_gaw

    if DEMO_GAW.exists():
        return DEMO_GAW
    return make_demo_gaw(tmp_path_factory.mktemp("gaw") / "demo_gaw.csv")


def run_job(http, spec: dict) -> tuple[str, dict, dict]:
    """Submit ``spec`` as alice, wait for it, and return (job id, samples JSON, posterior summary)."""
    r = http.post("/jobs", json=spec, headers=auth("alice"))
    assert r.status_code == 202, r.text
    job_id = r.json()["id"]
    st = wait_done(http, job_id, "alice", timeout=900)
    assert st["state"] == "done", st
    js = http.get(f"/jobs/{job_id}/samples", params={"format": "json"}, headers=auth("alice")).json()
    return job_id, js, http.get(f"/jobs/{job_id}/posterior", headers=auth("alice")).json()


def test_fe_job_equals_direct_vfcore(service, demo_gaw):
    from vfcore.data import demo_spec_dict
    from vfcore.inference.importance import importance_sample
    from worker.jobspec import JobSpec

    # a cheaper model than the demo's own (this test checks service == direct, not accuracy)
    spec = demo_spec_dict(n=N, path=demo_gaw, chunk_size=20, mesh="coarse", dt=1e-4, duration=0.3, discard=0.15)
    http, client = service.http, service.client
    job_id, js, post = run_job(http, spec)

    problem = JobSpec.model_validate(spec).to_problem()

    def dask_map(fn, items):
        return client.gather(client.map(fn, list(items), pure=False))

    direct = importance_sample(problem, n=N, seed=spec["seed"], map=dask_map, chunk_size=32)
    np.testing.assert_array_equal(np.array(js["samples"]), direct.samples)
    np.testing.assert_array_equal(np.array(js["resampled"]), direct.resampled)
    lw = np.array([-np.inf if v is None else v for v in js["log_weights"]])
    np.testing.assert_array_equal(lw, direct.log_weights)
    assert post["n_simulations"] == N and post["n_failed"] == direct.n_failed
    assert post["predictive"]["max_contact"]["mean"] > 0 and post["predictive"]["mean_flow"]["mean"] > 0
    assert post["model"]["contact"] == "projection" and "contact_layer_mm" not in post["model"]
    assert post["predictive"]["max_contact"]["depends_on"] == "mesh and time step"
    # the regularity check at the heaviest sample (7 simulations in the reducer) equals vfcore's
    from vfcore.diagnose.regularity import sensitivity

    reg = sensitivity(problem, direct.samples[int(np.argmax(direct.log_weights))], seed=spec["seed"])
    assert post["regularity"]["n_simulations"] == 7
    assert post["regularity"]["loglik"] == pytest.approx(reg.loglik, rel=1e-12, abs=1e-9)
    assert post["regularity"]["irregular"] is reg.irregular
    assert any("IRREGULAR VIBRATION" in w for w in post["warnings"]) is reg.irregular
    assert post["regularity"]["rough"] is reg.rough
    assert any("ROUGH LIKELIHOOD" in w for w in post["warnings"]) is (reg.rough and not reg.irregular)
    for name in ("gaw_fit", "corner", "contact_pressure"):
        assert http.get(f"/jobs/{job_id}/figures/{name}", headers=auth("alice")).status_code == 200


def test_fe_job_runs_the_contact_law_it_asks_for(service, demo_gaw, tmp_path):
    """A job with ``contact: layer`` is simulated with the compliant layer on the workers (its log-weights equal
    a direct run of the layer model and differ from the projection's), and its products say so: the nodal peak
    pressures depend on the mesh only, and the report names the law."""
    from vfcore.data import demo_spec_dict
    from vfcore.inference.importance import importance_sample
    from vfcore.inference.posterior import Posterior
    from worker.jobspec import JobSpec

    n = 24
    spec = demo_spec_dict(
        n=n,
        path=demo_gaw,
        chunk_size=12,
        mesh="coarse",
        dt=1e-4,
        duration=0.3,
        discard=0.15,
        contact="layer",
        contact_layer_mm=0.1,
    )
    http, client = service.http, service.client
    job_id, js, post = run_job(http, spec)
    lw = np.array([-np.inf if v is None else v for v in js["log_weights"]])

    def dask_map(fn, items):
        return client.gather(client.map(fn, list(items), pure=False))

    layer = JobSpec.model_validate(spec).to_problem()
    assert layer.config.contact == "layer" and layer.config.contact_layer_mm == 0.1
    direct = importance_sample(layer, n=n, seed=spec["seed"], map=dask_map, chunk_size=12)
    np.testing.assert_array_equal(lw, direct.log_weights)
    rigid = JobSpec.model_validate({**spec, "contact": "projection"}).to_problem()
    other = importance_sample(rigid, n=n, seed=spec["seed"], map=dask_map, chunk_size=12)
    np.testing.assert_array_equal(other.samples, direct.samples)  # the same draws ...
    assert not np.array_equal(other.log_weights, direct.log_weights)  # ... scored by another model
    assert post["model"]["contact"] == "layer" and post["model"]["contact_layer_mm"] == 0.1
    assert post["predictive"]["max_contact"]["depends_on"] == "mesh"
    nc = http.get(f"/jobs/{job_id}/samples", params={"format": "netcdf"}, headers=auth("alice"))
    path = tmp_path / "posterior.nc"
    path.write_bytes(nc.content)
    recorded = Posterior.from_netcdf(path).model  # what a later `diagnose --base` checks against
    assert recorded["contact"] == "layer" and layer.config.differences(recorded) == {}
    assert rigid.config.differences(recorded) == {"contact": ("layer", "projection")}
    html = http.get(f"/jobs/{job_id}/report", headers=auth("alice")).text
    assert "contact layer 0.1 mm" in html and "(depends on mesh)" in html
