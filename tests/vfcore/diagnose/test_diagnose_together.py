"""Extended fits run together (vfcore.diagnose.together): each equals its fit alone, bit for bit."""

import numpy as np
import pytest

from vfcore.config import SimConfig
from vfcore.diagnose.fit import ExtendedEvaluator, fit_extended
from vfcore.diagnose.together import ExtendedPool, fit_extended_many
from vfcore.forward import simulate
from vfcore.inference import Prior
from vfcore.inference.importance import BalancedMap
from vfcore.inference.problem import Problem
from vfcore.params import PARAM_NAMES, TABLE3
from vfcore.result import HR_OVERSAMPLE

FPS = 2000.0
CFG = SimConfig(mesh="coarse", dt=1e-4, duration=0.25, discard=0.15)
#: one entry of each way an entry simulates: the base model (scale, asymmetry: observation), its own
#: configuration per draw (sep_ratio), two folds per draw (lr_stiffness)
ENTRIES = ("scale", "sep_ratio", "lr_stiffness", "asymmetry")


@pytest.fixture(scope="module")
def problem():
    prior = Prior.default(fixed={n: getattr(TABLE3, n) for n in PARAM_NAMES if n not in ("E_cover", "p_sub")})
    run = simulate(TABLE3, CFG)
    rng = np.random.default_rng(3)
    y = 1.05 * np.asarray(run.gaw_hr[37::HR_OVERSAMPLE][:100]) + 0.4 * rng.standard_normal(100)
    return Problem(y, FPS, prior, config=CFG)


def _same(a, b):
    assert a.samples.tobytes() == b.samples.tobytes()
    assert float(a.log_evidence) == float(b.log_evidence)
    assert float(a.log_evidence_se) == float(b.log_evidence_se)
    assert int(a.n_simulations) == int(b.n_simulations)
    assert a.info["extension"] == b.info["extension"]
    assert a.info.get("integrated") == b.info.get("integrated")
    assert a.info["n_generations"] == b.info["n_generations"]


def test_the_pool_scores_each_row_as_its_own_evaluator(problem):
    evs = [ExtendedEvaluator(problem, n, integrate=True) for n in ENTRIES]
    pool = ExtendedPool(evs)
    rng = np.random.default_rng(0)
    batches = [(j, ev.prior.sample(3 + j, rng)) for j, ev in enumerate(evs)]
    rows, where = pool.rows(batches)
    assert rows.shape == (3 + 4 + 5 + 6, 1 + max(ev.prior.ndim for ev in evs))
    assert list(rows[:4, 0]) == [0, 1, 2, 3]  # interleaved: one row of each batch in turn
    ev = pool(rows)
    for (j, th), idx in zip(batches, where):
        alone = evs[j](th)
        mine = pool.take(ev, j, idx)
        for name in ("loglik", "ok", "gaw", "mean_flow", "max_contact", "extra", "contact_impulse"):
            a, b = getattr(alone, name), getattr(mine, name)
            assert (a is None) == (b is None), name
            if a is not None:
                assert a.shape == b.shape and a.tobytes() == b.tobytes(), (ENTRIES[j], name)


def test_fits_run_together_equal_each_fit_alone(problem):
    jobs = [(n, 10, 40 + i) for i, n in enumerate(ENTRIES[:3])]
    split = BalancedMap(map, 2)  # every batch in two equal parts, as on 2 workers
    batches = []

    def counting(fn, parts):
        parts = list(parts)
        batches.append(sum(np.shape(p)[0] for p in parts))
        return split(fn, parts)

    done = []
    together = fit_extended_many(
        problem, jobs, map=counting, chunk_size=8, max_moves=2, on_done=lambda i, post: done.append(i)
    )
    n_together = len(batches)
    alone = [fit_extended(problem, n, n_particles=k, seed=s, map=split, chunk_size=8, max_moves=2) for n, k, s in jobs]
    for a, b in zip(together, alone):
        _same(a, b)
    assert sorted(done) == [0, 1, 2]
    # one map call a round: as many as the longest fit's batches, not the sum of all fits'
    per_fit = [int(p.info["n_generations"]) for p in alone]
    assert n_together < sum(per_fit) * 2
    assert sum(batches) == sum(int(p.n_simulations) for p in alone)


def test_fits_run_together_refuse_options_that_are_not_the_samplers(problem):
    with pytest.raises(ValueError, match="screen"):
        fit_extended_many(problem, [("scale", 12, 1)], screen=problem)


@pytest.mark.slow  # the same machinery as the refits together, with a reference per fit
def test_rescues_run_together_equal_each_rescue_alone(problem):
    """Reference-started refits (the rescue) of two entries, run together, equal each one alone."""
    from types import SimpleNamespace

    from vfcore.diagnose.mode_fits import reference_refit, reference_refits

    names = problem.prior.names
    mid = 0.5 * (problem.prior.lo + problem.prior.hi)
    base = SimpleNamespace(names=names, mean=mid, cov=np.diag((0.05 * problem.prior.width) ** 2))
    jobs = [("scale", 10, 7), ("sep_ratio", 10, 9)]
    together = reference_refits(problem, base, jobs, map=BalancedMap(map, 2), chunk_size=8, max_moves=2)
    for (name, n, seed), (z, se, post) in zip(jobs, together):
        z1, se1, alone = reference_refit(
            problem, base, name, n_particles=n, seed=seed, map=BalancedMap(map, 2), chunk_size=8, max_moves=2
        )
        assert (z, se) == (z1, se1)
        _same(post, alone)
        assert post.info["reference"] == alone.info["reference"]


@pytest.mark.slow  # the same machinery as the refits together, with a reference per fit
def test_continued_fits_run_together_equal_each_fit_alone(problem):
    """The continuation stage's fits from each entry's optimum, run together, equal each fit alone."""
    from vfcore.diagnose.search import SearchResult, continued_fit, continued_fits, model_prior

    jobs = []
    for k, (name, seed) in enumerate((("scale", 3), ("sep_ratio", 4))):
        prior = model_prior(problem, name)
        theta = prior.lo + (0.4 + 0.1 * k) * prior.width
        jobs.append((SearchResult(tuple(prior.names), theta, -100.0, 50), name, seed))
    together = continued_fits(problem, jobs, n_particles=10, map=BalancedMap(map, 2), chunk_size=8, max_moves=2)
    for (found, name, seed), (z, se, post) in zip(jobs, together):
        z1, se1, alone = continued_fit(
            problem, found, name, n_particles=10, seed=seed, map=BalancedMap(map, 2), chunk_size=8, max_moves=2
        )
        assert (z, se) == (z1, se1)
        _same(post, alone)
        assert post.info["continuation"] == alone.info["continuation"]
