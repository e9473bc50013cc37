"""The store of batch evaluations (vfcore.inference.memo.CachedMap): a rerun reads back what was
simulated, an interrupted run resumes, and a diagnosis resumed from the store is bit-identical."""

import pickle
import threading

import numpy as np
import pytest

from vfcore.inference.memo import CachedMap, account
from vfcore.inference.problem import Evaluation

CALLS = []


class _Square:
    """A batch function: log-likelihood -offset * sum(x^2); records each part it is given."""

    def __init__(self, offset=1.0):
        self.offset = offset

    def __call__(self, rows):
        CALLS.append(len(rows))
        return Evaluation.from_loglik(-self.offset * np.sum(np.asarray(rows) ** 2, axis=1))


def _parts(n=5, seed=0):
    return np.array_split(np.random.default_rng(seed).standard_normal((23, 3)), n)


def _same(a: list, b: list) -> bool:
    return len(a) == len(b) and all(x.loglik.tobytes() == y.loglik.tobytes() for x, y in zip(a, b))


def test_a_second_run_reads_every_part_back_and_a_changed_function_or_part_is_simulated(tmp_path):
    CALLS.clear()
    first = CachedMap(map, tmp_path)(_Square(), _parts())
    assert CALLS == [5, 5, 5, 4, 4]
    again = CachedMap(map, tmp_path)
    CALLS.clear()
    assert _same(again(_Square(), _parts()), first) and CALLS == [] and (again.hits, again.misses) == (5, 0)
    # another function (different offset) or other parameters are other keys: simulated, not read back
    other = again(_Square(2.0), _parts())
    assert CALLS == [5, 5, 5, 4, 4] and again.misses == 5
    assert np.allclose(other[0].loglik, 2.0 * first[0].loglik)
    p = _parts()
    p[2] = p[2] + 1e-12  # one parameter moved by 1e-12
    CALLS.clear()
    again(_Square(), p)
    assert CALLS == [5]


def test_a_store_left_by_other_code_is_not_read(tmp_path, monkeypatch):
    import vfcore.inference.memo as M

    CachedMap(map, tmp_path)(_Square(), _parts())
    assert [p.name for p in tmp_path.iterdir()] == [M.code_fingerprint()[:16]]
    monkeypatch.setattr(M, "code_fingerprint", lambda: "f" * 64)  # as after an upgrade of vfcore
    other = CachedMap(map, tmp_path)
    other(_Square(), _parts())
    assert (other.hits, other.misses) == (0, 5)


class Killed(Exception):
    """A worker that died."""


def dies_after(k):
    """A map whose worker dies before its ``k``-th part."""

    def inner(fn, parts):
        for i, part in enumerate(parts):
            if i == k:
                raise Killed
            yield fn(part)

    return inner


def test_an_interrupted_run_resumes_from_the_parts_it_finished(tmp_path):
    with pytest.raises(Killed):
        CachedMap(dies_after(3), tmp_path)(_Square(), _parts())
    resumed = CachedMap(map, tmp_path)
    CALLS.clear()
    out = resumed(_Square(), _parts())
    assert (resumed.hits, resumed.misses) == (3, 2) and CALLS == [4, 4]
    assert _same(out, list(map(_Square(), _parts())))
    assert not list(tmp_path.rglob("*.tmp"))  # nothing half-written is left


class _Slow(_Square):
    """_Square that takes ``delay`` seconds a part."""

    def __init__(self, delay):
        super().__init__()
        self.delay = delay

    def __call__(self, rows):
        import time

        time.sleep(self.delay)
        return super().__call__(rows)


def test_a_resumed_run_counts_the_wall_time_of_the_attempts_before_it(tmp_path, monkeypatch):
    import time

    from vfcore.inference import memo

    monkeypatch.setattr(memo, "NOTE_EVERY_S", 0.0)  # note every part
    fn = _Slow(0.05)
    t0 = time.perf_counter()
    with pytest.raises(Killed):
        CachedMap(dies_after(3), tmp_path)(fn, _parts())
    first = time.perf_counter() - t0
    # the first attempt is counted up to its third stored part: 3 parts of 0.05 s at least, and
    # no more than the attempt lasted
    second = CachedMap(map, tmp_path)
    assert second.earlier_attempts == 1 and 0.15 <= second.earlier_wall_s <= first
    t1 = time.perf_counter()
    second(fn, _parts())
    rep = account({"wall_s": time.perf_counter() - t1}, second)
    assert rep["resume_store"]["parts_read"] == 3 and rep["resume_store"]["parts_simulated"] == 2
    assert rep["wall_s"] == pytest.approx(rep["resume_store"]["this_attempt_wall_s"] + second.earlier_wall_s)
    assert 0.25 <= rep["wall_s"] <= time.perf_counter() - t0
    # a third attempt sees both; an unreadable record counts 0 s and breaks nothing
    (second.root / "attempts" / "zz-broken.json").write_text("{not json")
    third = CachedMap(map, tmp_path)
    assert third.earlier_attempts == 3 and third.earlier_wall_s >= 0.25
    assert account({"wall_s": 1.0}, None) == {"wall_s": 1.0}  # no store: unchanged


def test_the_attempt_record_is_rewritten_at_most_every_few_seconds_and_after_each_call(tmp_path, monkeypatch):
    import json

    from vfcore.inference import memo

    monkeypatch.setattr(memo, "NOTE_EVERY_S", 3600.0)

    def records(store):
        return [json.loads(f.read_text()) for f in (store.root / "attempts").glob("*.json")]

    with pytest.raises(Killed):  # killed inside a call: nothing noted since the start
        dying = CachedMap(dies_after(3), tmp_path)
        dying(_Square(), _parts())
    assert [r["parts_stored"] for r in records(dying)] == [0]
    whole = CachedMap(map, tmp_path)  # a call that ends is always noted
    whole(_Square(), _parts())
    assert sorted(r["parts_stored"] for r in records(whole)) == [0, 2]  # 3 read back, 2 stored


def test_an_unreadable_entry_is_simulated_again_and_an_unpicklable_function_runs_uncached(tmp_path):
    cm = CachedMap(map, tmp_path)
    cm(_Square(), _parts())
    victim = sorted(tmp_path.rglob("*.pkl"))[0]
    victim.write_bytes(b"not a pickle")
    cm2 = CachedMap(map, tmp_path)
    assert _same(cm2(_Square(), _parts()), list(map(_Square(), _parts()))) and cm2.misses == 1
    assert pickle.loads(victim.read_bytes()).loglik.shape[0] in (4, 5)  # rewritten whole

    class Locked(_Square):
        def __init__(self):
            super().__init__()
            self.lock = threading.Lock()  # neither pickle nor cloudpickle takes a lock

    cm3 = CachedMap(map, tmp_path)
    assert _same(cm3(Locked(), _parts()), list(map(_Square(), _parts())))
    assert cm3.uncached == 5 and cm3.hits == cm3.misses == 0
    # a part that is not a numeric array (its bytes would be object addresses) is not cached
    objs = [np.array([[1.0]], dtype=object), np.zeros((1, 1))]
    assert len(cm3(lambda rows: len(rows), objs)) == 2 and cm3.uncached == 7


def test_a_map_that_drops_results_is_an_error(tmp_path):
    with pytest.raises(RuntimeError, match="returned 2 results for 5 parts"):
        CachedMap(lambda fn, parts: [fn(p) for p in parts[:2]], tmp_path)(_Square(), _parts())


@pytest.mark.slow
def test_a_diagnosis_resumed_from_the_store_is_bit_identical(tmp_path):
    """A small blind diagnosis (a recording seen 10 % too large; continuation search on) run
    through the store, interrupted part-way in a second run, resumed in a third: the third reads
    back what the first two simulated, simulates nothing else, and its report is the first's."""
    import json

    from vfcore.config import SimConfig
    from vfcore.diagnose.pipeline import diagnose
    from vfcore.forward import simulate
    from vfcore.inference import Prior
    from vfcore.inference.problem import Problem
    from vfcore.params import PARAM_NAMES, TABLE3
    from vfcore.result import HR_OVERSAMPLE

    cfg = SimConfig(mesh="coarse", dt=1e-4, duration=0.35, discard=0.15)
    run = simulate(TABLE3, cfg)
    y = 1.1 * np.asarray(run.gaw_hr[29::HR_OVERSAMPLE][:200]) + 0.3 * np.random.default_rng(3).standard_normal(200)
    prior = Prior.default(fixed={n: getattr(TABLE3, n) for n in PARAM_NAMES if n != "E_cover"})
    pb = Problem(y, 2000.0, prior, config=cfg, sigma_e=0.3)
    small = {"n_design": 4, "n_keep": 1, "maxfev0": 6, "maxfev_step": 3}

    def go(mapper, progress=None):
        rep = diagnose(
            pb,
            free_material=False,
            n_particles=12,
            refit_particles=10,
            seed=3,
            candidates=["scale"],
            base_runs=1,
            map=mapper,
            continuation=True,
            continuation_options=small,
            progress=progress,
        )

        def strip(x):  # wall times are the only clock readings
            if isinstance(x, dict):
                return {k: strip(v) for k, v in x.items() if k != "wall_s"}
            return [strip(v) for v in x] if isinstance(x, (list, tuple)) else x

        return json.dumps(strip(rep.to_dict()), sort_keys=True, default=float)

    first = CachedMap(map, tmp_path / "a")
    ref = go(first)
    n = first.misses
    assert n > 10 and first.hits == 0 and first.uncached == 0  # every part of a diagnosis is stored

    class Killed(Exception):
        pass

    done = []

    def dies(fn, parts):  # a worker killed after n // 2 parts
        for part in parts:
            if len(done) >= n // 2:
                raise Killed
            done.append(1)
            yield fn(part)

    with pytest.raises(Killed):
        go(CachedMap(dies, tmp_path / "b"))
    resumed = CachedMap(map, tmp_path / "b")
    events = []
    assert go(resumed, events.append) == ref  # progress reporting changes nothing
    assert resumed.hits == n // 2 and resumed.misses == n - n // 2
    replay = CachedMap(lambda fn, parts: pytest.fail("simulated on a replay"), tmp_path / "a")
    with pytest.warns(RuntimeWarning, match="progress callback raised ZeroDivisionError"):
        assert go(replay, lambda ev: 1 / 0) == ref and replay.hits == n  # a broken display neither
    # the stages in order, the counts only growing, one report after each of the n parts
    stages = [(e["stage"], e["entry"], e["step"], e["steps"]) for e in events]
    assert [s for i, s in enumerate(stages) if i == 0 or s != stages[i - 1]] == [
        ("base fit", None, None, None),
        ("regularity check", None, None, None),
        ("screening", None, None, 1),
        ("refit", "scale", 1, 1),
        ("continuation", "base", 0, 1),
        ("continuation", "entries", 1, 1),
        ("continuation", "scale", 1, 1),
        ("mode check", "scale", None, None),
        ("done", None, None, None),
    ]
    sims = [e["simulations"] for e in events]
    assert sims == sorted(sims) and sims[-1] >= n and len(set(sims)) == n + 1
    assert [e["elapsed_s"] for e in events] == sorted(e["elapsed_s"] for e in events)
    # the report's cost: every row evaluated is booked to exactly one stage and one entry
    cost = json.loads(ref)["cost"]
    assert set(cost["by_stage"]) == {"base fit", "regularity check", "screening", "refit", "continuation", "mode check"}
    assert set(cost["by_entry"]) == {"-", "scale", "base", "entries"}
    for book in cost.values():
        assert sum(v["simulations"] for v in book.values()) == sims[-1]


_DIGESTS = r"""
import numpy as np
from vfcore.config import SimConfig
from vfcore.diagnose.extensions import CATALOGUE
from vfcore.diagnose.fit import ExtendedEvaluator
from vfcore.diagnose.search import CONTINUATION, _Continuer, model_evaluator, model_prior, window_problems
from vfcore.inference import Prior
from vfcore.inference.importance import batch_function
from vfcore.inference.memo import _fn_digest
from vfcore.inference.problem import Problem
from vfcore.params import PARAM_NAMES, TABLE3
cfg = SimConfig(mesh="coarse", dt=1e-4, duration=0.35, discard=0.15)
prior = Prior.default(fixed={n: getattr(TABLE3, n) for n in PARAM_NAMES if n not in ("E_cover", "p_sub")})
pb = Problem(np.sin(np.linspace(0, 40, 200)) + 2.0, 2000.0, prior, config=cfg, sigma_e=0.3)
fns = [batch_function(pb)]
fns += [ExtendedEvaluator(pb, n, integrate=i) for n in CATALOGUE for i in (False, True)]
for ext in (None, *CATALOGUE):
    evs = [model_evaluator(p, ext, True) for p in window_problems(pb, 3.0)]
    fns.append(_Continuer(evs, {**CONTINUATION, "prior": model_prior(pb, ext, True)}))
print(len(fns), *(_fn_digest(f).hex() for f in fns))
"""


def test_the_diagnosis_batch_functions_have_the_same_key_in_a_new_process():
    """A resumed run is a new process, where str hashes are salted differently: the keys of the
    base, every catalogue entry (sampled and integrated) and every continuation search must not
    depend on that, or nothing would ever be read back."""
    import os
    import subprocess
    import sys

    outs = []
    for salt in ("1", "2"):
        env = {**os.environ, "PYTHONHASHSEED": salt}
        r = subprocess.run([sys.executable, "-c", _DIGESTS], env=env, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr[-2000:]
        outs.append(r.stdout.split())
    assert int(outs[0][0]) >= 20 and "None" not in outs[0]
    assert outs[0] == outs[1]
