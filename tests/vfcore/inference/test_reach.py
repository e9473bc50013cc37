"""The model's reach (vfcore.inference.reach): the verdict on synthetic ensembles, the phonation rule, the
on-disk cache (round trip, atomic writes, key sensitivity) and the shipped ensembles."""

from __future__ import annotations

import math
import os
import re
from types import SimpleNamespace

import numpy as np
import pytest

from vfcore.config import SimConfig
from vfcore.inference import reach as rc
from vfcore.inference.prior import Prior
from vfcore.params import PARAM_NAMES

CFG = SimConfig(mesh="coarse", dt=1e-4, duration=0.55, discard=0.25)
SHIPPED = rc.SHIPPED_DIR


@pytest.fixture(autouse=True)
def empty_cache(tmp_path, monkeypatch):
    """An empty user cache, and no shipped ensembles (the last test puts them back)."""
    monkeypatch.setenv("VFINFER_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(rc, "SHIPPED_DIR", tmp_path / "shipped")
    return tmp_path / "cache" / "reach"


def synthetic(n_phon=150, n_quiet=50, correlated=False, seed=0):
    """A hand-made ensemble: phonating draws with f0 55-80 Hz, peak area 10-50 mm^2, OQ 0.3-0.8, SQ 1-4,
    ClQ 0.1-0.3 (uniform, or f0 and area rising together), then non-phonating draws without measures."""
    rng = np.random.default_rng(seed)
    u = np.linspace(0, 1, n_phon) if correlated else rng.random(n_phon)
    v = u if correlated else rng.random(n_phon)
    meas = {
        "f0_hz": 55 + 25 * u,
        "max_area_mm2": 10 + 40 * v,
        "open_quotient": 0.3 + 0.5 * rng.random(n_phon),
        "speed_quotient": 1 + 3 * rng.random(n_phon),
        "closing_quotient": 0.1 + 0.2 * rng.random(n_phon),
    }
    meas = {k: np.concatenate([a, np.full(n_quiet, np.nan)]) for k, a in meas.items()}
    n = n_phon + n_quiet
    prior = Prior.default()
    return rc.ReachEnsemble(
        config=rc.config_key_dict(CFG),
        prior=prior.to_dict(),
        params=prior.full_array(prior.sample(n, rng)),
        ok=np.ones(n, bool),
        phonates=np.arange(n) < n_phon,
        measures=meas,
        seed=seed,
    )


def rec_at(ens, **over):
    """A recording at the ensemble's medians, with ``over`` replacing some measures."""
    st = ens.stats()
    return {**{c: st[c]["q50"] for c, *_ in rc.MEASURES}, **over}


def test_inside():
    ens = synthetic()
    v = rc.check_reach(rec_at(ens), ens)
    assert v.verdict == "inside" and not v.outside and v.hints == []
    assert all(m["verdict"] == "inside" for m in v.measures.values())
    assert v.n_near > 0 and "inside this model's reach" in v.message


def test_outside_high_f0_names_the_numbers_and_what_would_help():
    ens = synthetic()
    st = ens.stats()["f0_hz"]
    v = rc.check_reach(rec_at(ens, f0_hz=200.0), ens)
    assert v.verdict == "outside" and v.outside
    assert v.measures["f0_hz"]["verdict"] == "outside" and v.measures["max_area_mm2"]["verdict"] == "inside"
    assert (
        f"recording f0 200 Hz; this model and prior reach {st['q05']:.0f}-{st['q95']:.0f} Hz (5-95 %), "
        f"at most {st['max']:.0f} Hz"
    ) in v.message
    assert "150 of 200 prior draws phonate" in v.message
    assert "soft synthetic" in v.message and "--prior E_body" in v.message
    assert "\n" not in v.message


def test_outside_low_f0_and_small_area():
    ens = synthetic()
    v = rc.check_reach(rec_at(ens, f0_hz=30.0, max_area_mm2=1.0), ens)
    assert v.verdict == "outside"
    assert re.search(r"recording f0 30 Hz; .* at least 5\d Hz", v.message)
    assert "recording peak area 1 mm^2" in v.message and "calibration" in v.message
    assert "lower the stiffness" in v.message and "soft synthetic" not in v.message


def test_marginal_beyond_95_percent_but_below_the_max():
    ens = synthetic()
    st = ens.stats()["f0_hz"]
    x = 0.5 * (st["q95"] + st["max"])
    v = rc.check_reach(rec_at(ens, f0_hz=x), ens)
    assert v.verdict == "marginal" and v.measures["f0_hz"]["verdict"] == "marginal"
    assert "margin of this model's reach" in v.message and f"at most {st['max']:.0f} Hz" in v.message


def test_quotient_outside_is_marginal_not_outside():
    ens = synthetic()
    v = rc.check_reach(rec_at(ens, open_quotient=0.99), ens)
    assert v.measures["open_quotient"]["verdict"] == "outside"
    assert v.verdict == "marginal"


def test_no_draw_near_in_f0_and_area_together_is_marginal():
    ens = synthetic(correlated=True)
    v = rc.check_reach(rec_at(ens, f0_hz=58.0, max_area_mm2=45.0), ens)
    assert v.measures["f0_hz"]["verdict"] == "inside" and v.measures["max_area_mm2"]["verdict"] == "inside"
    assert v.n_near == 0 and v.verdict == "marginal" and "together" in v.message


@pytest.mark.parametrize("area_scale", [None, (0.25, 4.0)])
def test_a_measure_the_recording_lacks_is_no_verdict_and_no_error(area_scale):
    """A recording whose speed quotient could not be measured (NaN) is judged on the rest, with or
    without an unknown area scale."""
    ens = synthetic()
    v = rc.check_reach(rec_at(ens, speed_quotient=math.nan), ens, area_scale=area_scale)
    assert v.verdict == "inside" and v.measures["speed_quotient"]["verdict"] != "outside"


def test_unchecked_without_ensemble_and_only_outside_from_a_wider_prior():
    ens = synthetic()
    assert rc.check_reach(rec_at(ens), None).verdict == "unchecked"
    assert rc.check_reach(rec_at(ens), ens, exact=False).verdict == "unchecked"
    v = rc.check_reach(rec_at(ens, f0_hz=200.0), ens, exact=False)
    assert v.verdict == "outside" and "wider prior" in v.message


def test_no_phonating_draw_is_outside():
    ens = synthetic(n_phon=0, n_quiet=20)
    v = rc.check_reach({"f0_hz": 100.0, "max_area_mm2": 10.0}, ens)
    assert v.verdict == "outside" and "no prior draw of this model phonates" in v.message


def _sine(f0, fps=4000.0, dur=0.3, amp=20.0, decay=0.0):
    t = np.arange(int(dur * fps)) / fps
    return amp * np.exp(-decay * t) * 0.5 * (1 - np.cos(2 * np.pi * f0 * t))


def _fake(f0, f0_sim=None, decay=0.0):
    return SimpleNamespace(ok=True, gaw=_sine(f0, decay=decay), fps=4000.0, f0=f0 if f0_sim is None else f0_sim)


def test_phonation_rule():
    assert rc.draw_measures(_fake(70.0))[0]
    assert not rc.draw_measures(_fake(70.0, decay=15.0))[0]  # decays: a transient, not phonation
    assert not rc.draw_measures(_fake(420.0, f0_sim=60.0))[0]  # GAW pitch != the fold's cycle rate
    assert not rc.draw_measures(SimpleNamespace(ok=False, gaw=np.zeros(5), fps=4000.0, f0=math.nan))[0]
    ph, m = rc.draw_measures(_fake(70.0))
    assert abs(m["f0_hz"] - 70.0) < 0.5 and abs(m["max_area_mm2"] - 20.0) < 0.1


def fake_simulate(rows, config, block=32):
    """f0 = 6 E_body Hz, peak area p_sub / 50 mm^2; draws with E_cover > 900 Pa fail."""
    return [
        _fake(6.0 * r[0]) if r[1] <= 900 else SimpleNamespace(ok=False, gaw=np.zeros(0), fps=4000.0, f0=math.nan)
        for r in rows
    ]


def test_cache_round_trip_and_lookup(empty_cache):
    prior = Prior.default()
    seen = []
    ens = rc.build_ensemble(
        CFG, prior, n=40, seed=3, block=16, simulate_fn=fake_simulate, progress=lambda d, t, e: seen.append((d, t))
    )
    assert seen == [(16, 40), (32, 40), (40, 40)]
    assert ens.phonates.sum() == np.sum(ens.params[:, PARAM_NAMES.index("E_cover")] <= 900)
    assert rc.find_ensemble(CFG, prior) == (None, False)
    path = rc.save_cached(ens)
    assert path.parent == empty_cache and path.name == f"reach_{rc.reach_key(CFG, prior)}.csv"
    assert [p.name for p in empty_cache.iterdir()] == [path.name]  # no temporary left behind
    got, exact = rc.find_ensemble(CFG, prior)
    assert exact and got.key == ens.key and got.n == 40 and got.seed == 3
    np.testing.assert_allclose(got.params, ens.params, rtol=1e-9)
    np.testing.assert_array_equal(got.phonates, ens.phonates)
    for c, *_ in rc.MEASURES:
        np.testing.assert_allclose(got.measures[c], ens.measures[c], rtol=1e-5, equal_nan=True)
    assert got.stats()["f0_hz"]["max"] == pytest.approx(ens.stats()["f0_hz"]["max"], rel=1e-5)
    # a narrower prior (one parameter fixed inside the box) falls back on it, not exactly
    narrow = Prior.default(fixed={"E_lig": 1.808})
    assert rc.find_ensemble(CFG, narrow)[0].key == ens.key and rc.find_ensemble(CFG, narrow)[1] is False
    # a wider prior, or another configuration, does not
    wide = Prior({**prior.bounds, "E_body": (5.0, 15.0)})
    assert rc.find_ensemble(CFG, wide)[0] is None
    assert rc.find_ensemble(CFG.replace(dt=5e-5), prior)[0] is None


def test_failed_write_keeps_the_old_file(empty_cache, monkeypatch):
    ens = rc.build_ensemble(CFG, Prior.default(), n=8, simulate_fn=fake_simulate)
    path = rc.save_cached(ens)
    before = path.read_bytes()

    def boom(self):
        raise OSError("disk full")

    monkeypatch.setattr(rc.ReachEnsemble, "to_csv_text", boom)
    with pytest.raises(OSError):
        rc.save_cached(ens)
    assert path.read_bytes() == before and [p.name for p in empty_cache.iterdir()] == [path.name]


def test_tampered_key_is_refused(empty_cache):
    ens = rc.build_ensemble(CFG, Prior.default(), n=8, simulate_fn=fake_simulate)
    path = rc.save_cached(ens)
    path.write_text(path.read_text().replace(f'# key: "{ens.key}"', '# key: "0000000000000000"'))
    with pytest.raises(ValueError, match="does not match"):
        rc.ReachEnsemble.load(path)


def test_key_sensitivity():
    p = Prior.default()
    k = rc.reach_key(CFG, p)
    assert rc.reach_key(CFG.replace(fps=2000.0), p) == k  # the camera rate is not physics
    assert rc.reach_key(CFG.replace(keep_trajectories=True), p) == k
    assert rc.reach_key(CFG.replace(dt=1.0e-4), p) == k
    for other in (
        CFG.replace(dt=5e-5),
        CFG.replace(mesh="medium"),
        CFG.replace(element="anp"),
        CFG.replace(duration=0.5),
        CFG.replace(closure_gap_mm=0.0),
    ):
        assert rc.reach_key(other, p) != k
    assert rc.reach_key(CFG, Prior({**p.bounds, "p_sub": (400.0, 1801.0)})) != k
    assert rc.reach_key(CFG, Prior.default(fixed={"x0": 8.4})) != rc.reach_key(CFG, Prior.default(fixed={"x0": 8.3}))


def test_shipped_ensembles_cover_the_default_configurations(monkeypatch):
    """The ensembles in vfcore/data load, match their key, and put a 200-Hz sine outside the reach."""
    monkeypatch.setattr(rc, "SHIPPED_DIR", SHIPPED)
    for dt in (5e-5, 1e-4):
        cfg = SimConfig(mesh="coarse", dt=dt, duration=0.55, discard=0.25)
        ens, exact = rc.find_ensemble(cfg, Prior.default())
        assert exact and ens.n == rc.DEFAULT_N and os.path.dirname(ens.source) == str(rc.SHIPPED_DIR)
        assert 0.05 < ens.phonating_fraction < 0.9
        v = rc.check_reach(rc.recording_measures(_sine(200.0), 4000.0), ens)
        assert v.verdict == "outside" and "recording f0 200 Hz" in v.message
        st = ens.stats()
        v = rc.check_reach({c: st[c]["q50"] for c, *_ in rc.MEASURES}, ens)
        assert v.verdict in ("inside", "marginal")


def test_the_flow_rule_keys_the_ensemble_and_the_paper_rule_keeps_the_shipped_keys():
    """Ensembles made before the flow load was a setting are the paper's rule: its key leaves ``flow`` out, so a
    shipped ensemble still matches; the continuous load gets an ensemble of its own."""
    from vfcore.config import SimConfig
    from vfcore.inference.reach_ensemble import config_key_dict, reach_key

    prior = Prior.default()
    paper, cont = SimConfig(flow="paper"), SimConfig(flow="continuous")
    assert "flow" not in config_key_dict(paper) and config_key_dict(cont)["flow"] == "continuous"
    assert reach_key(paper, prior) != reach_key(cont, prior)
