"""Worker layer: job spec, store layout, chunk purity, resume without recomputation."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
import zarr

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "service"))
from svc_helpers import toy_spec  # noqa: E402

from worker import store as st  # noqa: E402
from worker.jobspec import JobSpec  # noqa: E402
from worker.run import chunk_size_for, evaluator_for, prepare, run_chunk, run_job  # noqa: E402


@pytest.fixture(scope="module")
def client():
    from distributed import Client, LocalCluster

    with (
        LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None) as cl,
        Client(cl, set_as_default=False) as c,
    ):
        yield c


def test_jobspec_roundtrip_and_version():
    spec = JobSpec.model_validate(toy_spec(n=100))
    again = JobSpec.from_json(spec.to_json())
    assert again == spec and again.version == 1
    assert json.loads(spec.to_json())["gaw"]["units"] == "mm2"
    pb = spec.to_problem()
    assert pb.prior.names == ("E_cover", "p_sub") and pb.sigma_e == 10.0
    with pytest.raises(ValueError, match="version"):
        JobSpec.model_validate({**toy_spec(), "version": 2})
    assert pb.noise == "fixed"  # the paper's Eq. 15 unless asked
    marg = JobSpec.model_validate({**toy_spec(n=100), "noise": "marginal", "sigma_bounds": [0.05, 50.0]})
    assert JobSpec.from_json(marg.to_json()) == marg
    pm = marg.to_problem()
    assert pm.noise == "marginal" and pm.sigma_bounds == (0.05, 50.0)


def test_marginal_noise_job_runs_through_the_worker(tmp_path, client):
    """The toy job (noise sd 0.5 mm^2 before clipping at zero area) with the noise sd integrated out:
    the store holds vfcore's marginal log-likelihoods (recomputed here from the stored predictions),
    and the amplitude parameter's posterior is narrower than under the too-large fixed sigma_e = 1."""
    from vfcore.inference.problem import marginal_gaussian_loglik

    base = {**toy_spec(n=400, chunk_size=100), "sigma_e": 1.0}
    out = {}
    for noise in ("fixed", "marginal"):
        spec = JobSpec.model_validate({**base, "noise": noise})
        path = tmp_path / f"{noise}.zarr"
        root, pb = prepare(path, noise, spec)
        run_job(client, noise, path, spec)
        g = zarr.open_group(str(path), mode="r")["batches/0"]
        out[noise] = (np.asarray(g["loglik"][...]), np.asarray(g["thetas"][...]), np.asarray(g["gaw"][...]), pb)
    ll, th, gaw, pb = out["marginal"]
    assert pb.noise == "marginal"
    for k in range(3):
        assert ll[k] == pytest.approx(
            marginal_gaussian_loglik(gaw[k].astype(float), pb.obs_compared, 0.01, 100.0), abs=1e-3
        )  # the stored predictions are float32

    def sd_of(ll, x):
        w = np.exp(ll - ll.max())
        w /= w.sum()
        return float(np.sqrt(np.sum(w * (x - np.sum(w * x)) ** 2)))

    i = pb.prior.names.index("p_sub")
    assert sd_of(ll, th[:, i]) < sd_of(out["fixed"][0], out["fixed"][1][:, i]) / 1.5
    # the published summaries: the residual RMS is the noise level (0.5 mm^2 before clipping at zero
    # area), so the fixed sigma_e = 1 job is warned that its posterior is too wide; the marginal one is not
    fixed, marg = st.read_summary(tmp_path / "fixed.zarr"), st.read_summary(tmp_path / "marginal.zarr")
    for s in (fixed, marg):
        assert 0.25 < s["noise_check"]["residual_rms"]["q50"] < 0.55, s["noise_check"]
    assert fixed["noise_check"]["noise"] == "fixed" and marg["noise_check"]["noise"] == "marginal"
    assert any(w.startswith("NOISE LEVEL") and "too wide" in w for w in fixed["warnings"]), fixed["warnings"]
    assert not any(w.startswith("NOISE LEVEL") for w in marg["warnings"]), marg["warnings"]


def test_chunk_size_is_a_function_of_the_spec():
    fe = JobSpec.model_validate({**toy_spec(n=50_000), "model": "fe", "model_options": None, "mesh": "coarse"})
    assert 1 <= chunk_size_for(fe) <= 50_000 // 16
    assert chunk_size_for(JobSpec.model_validate(toy_spec(n=100, chunk_size=7))) == 7
    # an FE SMC batch (200 particles) is cut into whole lock-step blocks, not 16 narrow chunks
    smc = JobSpec.model_validate(
        {
            **toy_spec(),
            "model": "fe",
            "model_options": None,
            "mesh": "medium",
            "sampler": {"kind": "smc", "n_particles": 200},
        }
    )
    assert chunk_size_for(smc) == 32


def test_recomputed_chunk_writes_identical_bytes(tmp_path):
    spec = JobSpec.model_validate(toy_spec(n=40, chunk_size=10))
    path = tmp_path / "j.zarr"
    root, pb = prepare(path, "j", spec)
    from vfcore.inference.importance import draw_prior

    th = draw_prior(pb.prior, 40, spec.seed)
    st.ensure_batch(root, 0, th)
    ev = evaluator_for(spec, pb)
    run_chunk(1, 10, th[10:20], store_path=str(path), b=0, evaluator=ev)
    files = sorted(p for p in (path / "batches" / "0").rglob("*") if p.is_file() and "/c/" in str(p))
    before = {p: p.read_bytes() for p in files}
    run_chunk(1, 10, th[10:20], store_path=str(path), b=0, evaluator=ev)
    after = {p: p.read_bytes() for p in files}
    assert before == after and len(before) == 11  # 4 theta chunks + 7 arrays of chunk 1
    assert st.done_mask(root["batches/0"]).tolist() == [False, True, False, False]
    attrs = zarr.open_group(str(path), mode="r").attrs
    assert JobSpec.model_validate(attrs["jobspec"]) == spec and attrs["chunk_size"] == 10
    g = root["batches/0"]
    assert g["gaw"].dtype == np.float32 and g["gaw"].shape == (40, pb.n_compare)


def test_resume_skips_done_chunks(tmp_path, client):
    spec = JobSpec.model_validate(toy_spec(n=60, chunk_size=10))
    path = tmp_path / "r.zarr"
    root, pb = prepare(path, "r", spec)
    from vfcore.inference.importance import draw_prior

    th = draw_prior(pb.prior, 60, spec.seed)
    st.ensure_batch(root, 0, th)
    ev = evaluator_for(spec, pb)
    for c in (0, 3):
        run_chunk(c, 10 * c, th[10 * c : 10 * c + 10], store_path=str(path), b=0, evaluator=ev)
    marker = path / "batches" / "0" / "loglik" / "c" / "0"
    mtime = marker.stat().st_mtime_ns
    stats = run_job(client, "r", path, spec)
    assert stats["chunks_skipped"] == 2 and stats["chunks_computed"] == 4
    assert marker.stat().st_mtime_ns == mtime  # not rewritten
    again = run_job(client, "r", path, spec)  # everything done: nothing recomputed
    assert again["chunks_computed"] == 0 and again["chunks_skipped"] == 6
    s = st.read_summary(path)
    assert s["n_simulations"] == 60 and len(s["table"]) == 2


def test_a_measured_job_scores_and_summarises_through_the_worker(tmp_path, client):
    """The same toy IS job with and without p_sub measured as 1000 +- 30 Pa: the stored log-likelihoods
    differ by exactly that Gaussian's log density at each stored draw's p_sub, the spec round-trips, and
    both published summaries carry the identifiability table (the measured one naming its anchor)."""
    from scipy import stats

    base = toy_spec(n=200, chunk_size=50)
    out = {}
    for name, meas in (("plain", {}), ("measured", {"p_sub": [1000.0, 30.0]})):
        spec = JobSpec.model_validate({**base, "measurements": meas})
        assert JobSpec.from_json(spec.to_json()) == spec
        path = tmp_path / f"{name}.zarr"
        run_job(client, name, path, spec)
        g = zarr.open_group(str(path), mode="r")["batches/0"]
        out[name] = (np.asarray(g["loglik"][...]), np.asarray(g["thetas"][...]), st.read_summary(path))
    (ll0, th0, s0), (ll1, th1, s1) = out["plain"], out["measured"]
    np.testing.assert_array_equal(th0, th1)
    i = s1["names"].index("p_sub")
    np.testing.assert_allclose(ll1 - ll0, stats.norm.logpdf(1000.0, th1[:, i], 30.0), rtol=0, atol=1e-9)
    for s in (s0, s1):
        ident = s["identifiability"]
        assert [r["name"] for r in ident["parameters"]] == ["E_cover", "p_sub"]
        assert ident["scale"]["names"] == ["E_cover", "p_sub"]
        assert [c["label"] for c in ident["combinations"]] == ["E_cover/p_sub"]
    assert s1["identifiability"]["scale"]["measured"] == ["p_sub"]
    assert any(a.startswith("measured p_sub = 1000") for a in s1["identifiability"]["anchors"])
    assert s0["identifiability"]["scale"]["measured"] == []


def test_expected_cost_is_measured_on_the_jobs_own_model():
    """The probe times the job's FE model here (positive, finite, and longer for a longer simulation);
    IS knows its count exactly, SMC gives the measured range per particle."""
    from worker.run import expected_simulations, probe_seconds_per_sim

    base = {**toy_spec(n=300), "model": "fe", "model_options": None, "mesh": "coarse", "dt": 1e-4}
    short = JobSpec.model_validate({**base, "duration": 0.3, "discard": 0.1})
    long = JobSpec.model_validate({**base, "duration": 1.2, "discard": 0.1})
    t_short, t_long = probe_seconds_per_sim(short), probe_seconds_per_sim(long)
    assert 0 < t_short < t_long < 60
    assert expected_simulations(short) == (300, 300)
    smc = JobSpec.model_validate({**base, "sampler": {"kind": "smc", "n_particles": 50}})
    assert expected_simulations(smc) == (1000, 4500)


def test_a_spec_builds_its_problem_once(monkeypatch):
    """Validation builds the job's Problem (it checks the recording against the simulated window); every
    stage that holds the spec shares that one (run, reducer checks), and it is not part of the spec's value."""
    import vfcore.inference.problem as P

    built = []
    post_init = P.Problem.__post_init__
    monkeypatch.setattr(P.Problem, "__post_init__", lambda self: (built.append(self), post_init(self))[1])
    spec = JobSpec.model_validate(toy_spec())
    assert len(built) == 1 and spec.to_problem() is built[0] and spec.to_problem() is built[0]
    again = JobSpec.from_json(spec.to_json())
    assert again == spec and len(built) == 2
    moved = spec.model_copy(update={"sigma_e": 3.0})
    assert moved.to_problem().sigma_e == 3.0 and spec.to_problem().sigma_e == 10.0


def test_an_smc_generation_is_cut_into_one_equal_chunk_per_worker_thread(tmp_path, client):
    """Each SMC generation of a job without a fixed chunk size goes out as one chunk per worker thread of the
    cluster (2 here), and the job's posterior is the one of the same job in fixed chunks of 7, bit for bit."""
    sampler = {"kind": "smc", "n_particles": 40}
    out = {}
    for name, kw in (("balanced", {}), ("fixed", {"chunk_size": 7})):
        spec = JobSpec.model_validate(toy_spec(sampler=sampler, **kw))
        path = tmp_path / f"{name}.zarr"
        prepare(path, name, spec)
        run_job(client, name, path, spec)
        batches = zarr.open_group(str(path), mode="r")["batches"]
        out[name] = (
            [
                (int(g.attrs["n"]), int(g.attrs["n_chunks"]))
                for _, g in sorted(batches.groups(), key=lambda kv: int(kv[0]))
            ],
            st.read_posterior_arrays(path),
        )
    shapes, post = out["balanced"]
    assert len(shapes) > 3 and all(c == min(2, n) for n, c in shapes), shapes
    assert all(c == -(-n // 7) for n, c in out["fixed"][0])
    assert [n for n, _ in shapes] == [n for n, _ in out["fixed"][0]]
    assert post.keys() == out["fixed"][1].keys()
    for k in post:
        np.testing.assert_array_equal(post[k], out["fixed"][1][k])
