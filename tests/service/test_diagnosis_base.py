"""A diagnosis job starts from the diagnosed job's own posterior (service.diagnosis.job_posterior)."""

from __future__ import annotations

import numpy as np

from service.diagnosis import job_posterior
from vfcore.inference.posterior import Posterior
from vfcore.inference.problem import Evaluation
from worker import store as st


def _posterior(with_gaws: bool) -> Posterior:
    rng = np.random.default_rng(0)
    samples = np.column_stack([rng.uniform(9, 15, 6), rng.uniform(250, 950, 6)])
    post = Posterior(
        names=("E_body", "E_cover"),
        samples=samples,
        log_weights=np.full(6, -np.log(6)),
        resampled=np.arange(6),
        ess=6.0,
        pareto_k=0.1,
        log_evidence=-123.4,
        log_evidence_se=0.5,
        n_simulations=6,
        method="smc",
        obs_gaw=np.linspace(0, 1, 20),
        fps=2000.0,
    )
    if with_gaws:
        g = rng.normal(size=(6, 20)).astype(np.float32)
        post.predictive = Evaluation(
            loglik=np.zeros(6),
            ok=np.ones(6, bool),
            gaw=g,
            mean_flow=np.ones(6),
            mean_contact=np.ones(6),
            max_contact=np.ones(6),
        )
        post.predictive_index = np.arange(6)
    return post


def test_the_jobs_posterior_is_read_back_with_its_predicted_gaws(tmp_path):
    store = tmp_path / "job.zarr"
    root = st.create_diagnosis_store(store, "job", "{}")
    assert job_posterior(store) is None  # a store without a posterior: fit the base
    post = _posterior(True)
    post.to_netcdf(tmp_path / "p.nc")
    st.write_blob(root, "posterior_nc", (tmp_path / "p.nc").read_bytes())
    got = job_posterior(store)
    assert got.names == post.names and got.log_evidence == post.log_evidence
    np.testing.assert_array_equal(got.samples, post.samples)
    np.testing.assert_array_equal(got.resampled_predictive().gaw, post.resampled_predictive().gaw)
    assert not list(tmp_path.glob(".*.nc"))  # the temporary file is gone
    _posterior(False).to_netcdf(tmp_path / "q.nc")
    st.write_blob(root, "posterior_nc", (tmp_path / "q.nc").read_bytes())
    assert job_posterior(store) is None  # no predicted GAWs: nothing to start from
