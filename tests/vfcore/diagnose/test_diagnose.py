"""vfcore.diagnose: phase-folded residuals, predictive p-values, extensions, evidence ranking.

Synthetic waveforms with analytically known answers; no FE simulation is run."""

import math

import numpy as np
import pytest

from vfcore import measures as M
from vfcore.diagnose import (
    CATALOGUE,
    NO_FINDING,
    PHASES,
    get,
    locate,
    measure_pvalues,
    phase_labels,
    predictive_measures,
    rank_extensions,
    residual_removed,
)
from vfcore.diagnose import extensions as X

FPS = 4000.0


def gaw_like(oq=0.6, amp=10.0, f0=100.0, n_cycles=8, fps=FPS, shift=0.3):
    """Half-sine pulses of open quotient ``oq`` and zero area in the closed phase."""
    t = np.arange(int(round(n_cycles * fps / f0))) / fps
    tau = ((t * f0 + shift) % 1.0) / f0  # time within the cycle
    to = oq / f0
    return np.where(tau < to, amp * np.sin(np.pi * tau / to), 0.0)


# ------------------------------------------------------------------ locate
def test_phase_labels_partition_cycle():
    g = gaw_like()
    codes, b = phase_labels(g, FPS)
    assert b.size >= 7
    inside = codes[b[0] : b[-1]]
    assert np.all(inside >= 0) and np.all(codes[: b[0]] == -1) and np.all(codes[b[-1] :] == -1)
    # closed fraction of a cycle ~ 1 - OQ (threshold 5 % of the half-sine: arcsin(0.05)/pi each side)
    closed = np.mean(inside == 0)
    assert closed == pytest.approx(0.4 + 0.6 * 2 * math.asin(0.05) / math.pi, abs=0.03)
    # opening precedes peak precedes closing in each cycle
    for k in range(b.size - 1):
        c = codes[b[k] : b[k + 1]]
        assert np.flatnonzero(c == 1).max() < np.flatnonzero(c == 2).min()
        assert np.flatnonzero(c == 2).max() < np.flatnonzero(c == 3).min()


def test_locate_closed_phase_leak_floor():
    base = gaw_like()
    obs = np.maximum(base, 1.0)  # incomplete closure: the area never drops below 1 mm^2
    rep = locate(obs, np.tile(base, (5, 1)), FPS)
    assert rep.dominant_phase == "closed"
    assert rep.energy_share["closed"] > 0.99
    assert rep.phase_rms["peak"] == pytest.approx(0.0, abs=1e-12)
    assert sum(rep.energy_share.values()) == pytest.approx(1.0)
    # folded profile: residual sits in the closed part of the cycle only (> 0 there, 0 near the peak)
    assert np.all(np.isfinite(rep.fold_mean)) and rep.fold_mean.size == 40
    assert rep.fold_mean.max() > 0.5 and rep.fold_mean.min() >= -1e-12
    assert np.sum(np.abs(rep.fold_mean) > 1e-9) < 0.5 * rep.fold_mean.size


def test_locate_peak_residual_goes_to_peak():
    base = gaw_like()
    pred = np.minimum(base, 9.5)  # prediction clipped below the observed peak
    rep = locate(base, pred, FPS)
    assert rep.dominant_phase == "peak"
    assert rep.energy_share["peak"] > 0.99
    assert rep.energy_share["closed"] == pytest.approx(0.0, abs=1e-12)


def test_locate_constant_offset_is_spread_over_the_cycle():
    """A constant offset has concentration 1 in every phase: no phase is named, and the fraction of
    the residual removed is taken over the whole cycle (halving the offset removes 3/4 of it)."""
    from vfcore.diagnose import SPREAD

    base = gaw_like()
    obs = base + 1.0
    rep = locate(obs, base, FPS)
    assert rep.dominant_phase == SPREAD
    assert all(c == pytest.approx(1.0) for c in rep.concentration().values())
    after = locate(obs, base + 0.5, FPS)
    assert residual_removed(rep, after) == pytest.approx(0.75)
    # a residual 1.5x as energetic per sample in the peak phase is concentrated there
    codes, _ = phase_labels(obs, FPS)
    bump = np.where(codes == 2, math.sqrt(1.5 * 1.0), 1.0)
    rep2 = locate(base + bump, base, FPS)
    assert rep2.concentration()["peak"] > 1.25 and rep2.dominant_phase == "peak"
    assert locate(base + bump, base, FPS, min_concentration=2.0).dominant_phase == SPREAD


# ------------------------------------------------------------------ p-values
def _ensemble(rng, k):
    oqs = rng.uniform(0.5, 0.7, k)
    amps = rng.uniform(8.0, 12.0, k)
    return np.array([gaw_like(o, a) for o, a in zip(oqs, amps)])


def test_pvalues_far_outside_and_inside():
    rng = np.random.default_rng(1)
    ens = _ensemble(rng, 100)
    hi = measure_pvalues(ens, gaw_like(oq=0.9), FPS, names=("open_quotient", "amplitude_mm2"))
    lo = measure_pvalues(ens, gaw_like(oq=0.3), FPS, names=("open_quotient",))
    assert hi["open_quotient"].p_upper == 0.0 and hi["open_quotient"].p_two_sided == 0.0
    assert lo["open_quotient"].p_upper == 1.0 and lo["open_quotient"].p_two_sided == 0.0
    assert hi["open_quotient"].n_draws == 100
    # amplitude of the oq=0.9 observation (10) is inside the ensemble's range
    assert 0.05 < hi["amplitude_mm2"].p_upper < 0.95
    # an observation from the same generator
    same = measure_pvalues(ens, _ensemble(np.random.default_rng(7), 1)[0], FPS, names=("open_quotient",))
    assert 0.05 < same["open_quotient"].p_upper < 0.95


def test_pvalues_uniform_under_the_generator():
    rng = np.random.default_rng(3)
    ens = _ensemble(rng, 100)
    draws = predictive_measures(ens, FPS, ("open_quotient",))["open_quotient"]
    obs = _ensemble(np.random.default_rng(4), 40)
    p = np.array([np.mean(draws >= M.gaw_measures(o, FPS)["open_quotient"]) for o in obs])
    assert 0.35 < p.mean() < 0.65
    assert np.mean((p > 0.05) & (p < 0.95)) > 0.75


def _replicates(fn, n, sigma_e, seed=11, noise=0.5):
    """Fraction of ``n`` noisy recordings ``fn(truth) + N(0, noise^2)`` whose two-sided p-value is
    below 0.05, per measure, against a tight posterior-predictive ensemble about the truth."""
    from vfcore.diagnose.locate import DEFAULT_MEASURES

    rng = np.random.default_rng(seed)
    ens = np.array(
        [
            gaw_like(
                0.6 + 0.002 * rng.standard_normal(),
                10 + 0.02 * rng.standard_normal(),
                f0=100 + 0.05 * rng.standard_normal(),
            )
            for _ in range(40)
        ]
    )
    truth = gaw_like()
    hits = {m: 0 for m in DEFAULT_MEASURES}
    for r in range(n):
        y = fn(truth) + noise * rng.standard_normal(truth.size)
        for m, c in measure_pvalues(ens, y, FPS, sigma_e=sigma_e, seed=r).items():
            hits[m] += c.p_two_sided < 0.05
    return {m: h / n for m, h in hits.items()}


def test_the_recordings_noise_estimated_from_it_calibrates_the_pvalues():
    """Recordings from the model itself (noise 0.5 mm^2): with the noise estimated from each
    recording every measure is flagged at about the nominal 5 %; with the likelihood's nominal
    sigma_e = 1 mm^2 as the replicates' noise, the noise-sensitive measures are flagged almost
    always. A leak and a scale error are still flagged, on the measures they change."""
    from vfcore.diagnose import noise_sd

    truth = gaw_like()
    y = truth + 0.5 * np.random.default_rng(0).standard_normal(truth.size)
    assert noise_sd(y, np.tile(truth, (3, 1))) == pytest.approx(0.5, rel=0.15)
    assert noise_sd(y + 1.5, truth) == pytest.approx(noise_sd(y, truth), abs=1e-12)  # a constant misfit: none of it
    assert noise_sd(0.85 * truth + (y - truth), truth) < 0.6  # a smooth misfit: little

    est = _replicates(lambda g: g, 40, "estimate")
    nominal = _replicates(lambda g: g, 40, 1.0)
    # 40 recordings: the nominal 5 % has a binomial sd of 3.4 %; measured 2.5-15 %, mean 7.5 %
    assert max(est.values()) <= 0.2 and np.mean(list(est.values())) <= 0.1, est
    assert nominal["glottal_gap_index"] >= 0.8 and nominal["min_area_mm2"] >= 0.8 and nominal["amplitude_mm2"] >= 0.8
    leak = _replicates(lambda g: g + 1.5, 20, "estimate")
    assert leak["glottal_gap_index"] >= 0.9 and leak["min_area_mm2"] >= 0.9 and leak["amplitude_mm2"] <= 0.2
    scale = _replicates(lambda g: 0.85 * g, 20, "estimate")
    assert scale["amplitude_mm2"] >= 0.9 and scale["min_area_mm2"] <= 0.3
    with pytest.raises(ValueError, match="sigma_e"):
        measure_pvalues(np.tile(truth, (3, 1)), y, FPS, sigma_e="residual")
    with pytest.raises(ValueError, match="sigma_e"):
        measure_pvalues(np.tile(truth, (3, 1)), y, FPS, sigma_e=-1.0)


def test_ties_count_half():
    """A measure equal in the recording and every draw (a glottal gap index of 0 everywhere) is
    not a disagreement: mid-p 0.5, two-sided 1."""
    g = gaw_like()
    pv = measure_pvalues(np.tile(g, (10, 1)), g, FPS, names=("glottal_gap_index", "min_area_mm2"))
    assert pv["glottal_gap_index"].p_upper == 0.5 and pv["glottal_gap_index"].p_two_sided == 1.0
    assert pv["min_area_mm2"].p_two_sided == 1.0


# ------------------------------------------------------------------ extensions
def test_leak_raises_minimum_exactly():
    g = gaw_like()
    out = get("leak").apply(g, {"leak_mm2": 1.7, "chink_fraction": 0.0}, fps=FPS)
    assert out.min() == pytest.approx(g.min() + 1.7, abs=1e-12)
    np.testing.assert_allclose(out - g, 1.7)  # a cartilaginous gap: constant
    assert M.glottal_gap_index(out, FPS) > 0.1 > M.glottal_gap_index(g, FPS)
    with pytest.raises(ValueError):
        get("leak").apply(g, {"leak_mm2": 5.0, "chink_fraction": 0.0}, fps=FPS)  # outside its 0-3 mm^2 prior
    with pytest.raises(ValueError, match="chink_fraction"):
        get("leak").apply(g, {"leak_mm2": 1.0, "chink_fraction": 1.5}, fps=FPS)
    with pytest.raises(ValueError, match="missing parameters"):
        get("leak").apply(g, {"leak_mm2": 1.0}, fps=FPS)


@pytest.mark.parametrize("gap_mm, chink_mm", [(0.2, 6.0), (0.05, 17.0), (0.6, 1.0)])
def test_membranous_chink_matches_a_strip_sum(gap_mm, chink_mm):
    """The chink model against the glottis summed strip by strip: a fold of length L = 17 mm whose
    membranous opening has width W(t) = A(t) / L everywhere, and a gap of width ``gap_mm`` over the
    last ``chink_mm`` of the length, is ``sum_y max(W, g(y)) dy``. That is the leak entry with
    area ``g l`` and chink fraction ``l / L``, hidden where the opening is wider than the gap."""
    L, n_y = 17.0, 3400
    y = (np.arange(n_y) + 0.5) * L / n_y
    g_y = np.where(y > L - chink_mm, gap_mm, 0.0)
    A = gaw_like()
    strips = np.maximum((A / L)[:, None], g_y[None, :]).sum(axis=1) * (L / n_y)
    out = get("leak").apply(A, {"leak_mm2": gap_mm * chink_mm, "chink_fraction": chink_mm / L}, fps=FPS)
    np.testing.assert_allclose(out, strips, atol=2e-3)
    # closed: the whole gap shows; open wider than the gap: none of it
    assert out[A == 0].size == 0 or np.allclose(out[A == 0], gap_mm * chink_mm, atol=2e-3)
    wide = A / L > gap_mm
    np.testing.assert_allclose(out[wide], A[wide], atol=1e-12)


def test_leak_flow_follows_the_open_part_of_the_chink():
    g = gaw_like()
    a, f, p = 1.5, 0.5, 800.0
    extra = X.leak_extra(g, a, f)
    q = X.leak_flow(extra, p)
    np.testing.assert_allclose(q, extra * 1e-6 * math.sqrt(2 * p / X.RHO_AIR))
    assert q.max() == pytest.approx(X.leak_flow(a - f * g.min(), p))


def test_leak_flow_bernoulli():
    q = X.leak_flow(2.0, 800.0)
    assert q == pytest.approx(2e-6 * math.sqrt(2 * 800.0 / X.RHO_AIR))


def test_exposure_sinc_factor():
    fps, f, n = 2000.0, 500.0, 400  # 100 whole periods
    t = np.arange(n) / fps
    x = np.sin(2 * np.pi * f * t + 0.3)
    for e in (0.25, 0.5, 1.0):
        y = X.apply_exposure(x, fps, e, edge="periodic")
        np.testing.assert_allclose(y, np.sinc(f * e / fps) * x, atol=1e-10)
    # default (reflected ends) is close in the interior
    y = get("exposure").apply(x, {"exposure_fraction": 1.0}, fps=fps)
    mid = slice(n // 4, 3 * n // 4)
    np.testing.assert_allclose(y[mid], np.sinc(f / fps) * x[mid], atol=0.03)
    assert np.sinc(f / fps) < 0.91  # the factor is not trivially 1


def test_scale_scales_area_measures_only():
    g = gaw_like() + 0.5
    m0 = M.gaw_measures(g, FPS)
    m1 = M.gaw_measures(get("scale").apply(g, {"scale": 1.15}, fps=FPS), FPS)
    for k in ("min_area_mm2", "max_area_mm2", "amplitude_mm2"):
        assert m1[k] == pytest.approx(1.15 * m0[k], rel=1e-12)
    for k in (
        "open_quotient",
        "speed_quotient",
        "closing_quotient",
        "naq",
        "amplitude_quotient_s",
        "glottal_gap_index",
        "hrf_db",
        "f0_hz",
    ):
        assert m1[k] == pytest.approx(m0[k], rel=1e-9, abs=1e-12)


def test_frame_rate_scales_f0():
    fps = 4000.0
    t = np.arange(1600) / fps
    x = np.sin(2 * np.pi * 120.0 * t)
    y = get("frame_rate").apply(x, {"rate_ratio": 1.05}, fps=fps)
    assert M.estimate_f0(y, fps) == pytest.approx(120.0 / 1.05, rel=5e-3)


def test_sep_ratio_resimulates_with_config():
    from vfcore import Params, SimConfig
    from vfcore.params import PARAM_NAMES

    seen = {}

    class Base:
        params = Params(**dict(zip(PARAM_NAMES, (12.15, 636.2, 1.808, 989.9, 1051, 3.079, 8.4))))
        config = SimConfig(sep_ratio=1.3)

    def fake_sim(p, cfg):
        seen["cfg"] = cfg
        return "sim"

    assert get("sep_ratio").apply(Base(), {"sep_ratio": 1.5}, simulate_fn=fake_sim) == "sim"
    assert seen["cfg"].sep_ratio == 1.5 and seen["cfg"].mesh == Base.config.mesh


def test_catalogue_complete_and_consistent():
    kinds = {"zipper": "observation", "asymmetry": "observation", "epithelium": "forward", "subglottal": "forward"}
    for name, kind in kinds.items():
        e = CATALOGUE[name]
        assert e.implemented and e.kind == kind
        # fitted through vfcore.diagnose.fit, not through apply()
        with pytest.raises(NotImplementedError, match="diagnose.fit"):
            e.apply(np.zeros(10), {p.name: p.lo for p in e.params}, fps=FPS)
    for e in CATALOGUE.values():
        assert set(e.phases) <= set(PHASES) and e.params
        assert all(p.lo < p.hi for p in e.params)
        assert set(e.measures) <= set(M.gaw_measures(gaw_like(), FPS))
    assert "leak" in X.matching(phase="closed")


# ------------------------------------------------------------------ rank
class _Post:
    def __init__(self, z, se):
        self.log_evidence, self.log_evidence_se = z, se


def test_rank_no_finding_within_noise():
    rep = rank_extensions(_Post(-100.0, 0.5), {"leak": _Post(-99.0, 0.5), "scale": _Post(-101.0, 0.4)})
    assert rep.winner is None and rep.verdict == NO_FINDING
    # a large gain that is Monte Carlo noise is not a finding either
    rep = rank_extensions((-100.0, 3.0), {"leak": (-94.0, 3.0)})
    assert rep.winner is None and rep.rows[0].delta == pytest.approx(6.0)
    assert rep.rows[0].delta_se == pytest.approx(math.sqrt(18.0))


def test_rank_names_large_gain():
    rep = rank_extensions(
        _Post(-100.0, 0.3),
        {"scale": _Post(-98.0, 0.3), "leak": _Post(-80.0, 0.4), "exposure": _Post(-95.0, 0.3)},
        residual={"leak": 0.9},
    )
    assert rep.winner == "leak"
    assert [r.name for r in rep.rows] == ["leak", "exposure", "scale"]
    assert rep.rows[0].delta_se == pytest.approx(0.5)
    assert "leak" in rep.verdict and "90 %" in rep.verdict
    assert rep.rows[1].found and not rep.rows[2].found  # exposure: d = 5 > 3 and > 3 * 0.42


def test_one_standard_error_rule_names_the_simpler_of_two_indistinguishable_fits():
    """Two found extensions whose evidence differs by less than one standard error: the one with
    fewer parameters is named (the richer one stays a rival); a gap beyond one se, equal
    parameter counts, or a simpler fit that was not found leave the winner alone."""
    from vfcore.diagnose.amend import prefer_parsimonious

    base = _Post(-1000.0, 0.5)
    nx = {"subglottal": 2, "epithelium": 1, "zipper": 2, "leak": 1}

    def rep(z_epith, se=30.0, **kw):
        fits = {
            "subglottal": _Post(-500.0, se),
            "epithelium": _Post(z_epith, se),
            "zipper": _Post(-520.0, se),
            "leak": _Post(-990.0, 0.5),
        }
        return rank_extensions(base, fits, n_extra=nx, k_se=3.0, **kw)

    r = rep(-510.0)  # 10 +- 42 below: indistinguishable
    assert r.winner == "subglottal"
    p = prefer_parsimonious(r, 1.0)
    assert p.winner == "epithelium" and p.physics == "epithelium"
    assert "one-standard-error" in p.notes[-1] and "subglottal" in p.notes[-1]
    assert "subglottal" in [f for f, _, _ in p.rivals]
    assert prefer_parsimonious(r, 0.0).winner == "subglottal"  # off
    assert prefer_parsimonious(rep(-560.0), 1.0).winner == "subglottal"  # 60 +- 42: beyond one se
    # equal counts (zipper, 20 +- 42 below) never displace the winner
    assert prefer_parsimonious(rep(-560.0), 1.0).rows[0].name == "subglottal"
    # a 1-parameter fit within one se that is not found (RMS only 10 % lower) is not named
    fits = {"subglottal": _Post(-500.0, 30.0), "leak": _Post(-505.0, 30.0)}
    r = rank_extensions(base, fits, n_extra=nx, rms={"subglottal": 0.5, "leak": 0.9}, base_rms=1.0)
    assert r.winner == "subglottal" and not next(x for x in r.rows if x.name == "leak").found
    assert prefer_parsimonious(r, 1.0).winner == "subglottal"


def test_rank_big_evidence_small_rms_gain_is_not_named():
    """The effect-size rule: a decisive evidence gain with a residual only 10 % smaller is not a
    finding; with 30 % or more it is; the larger dlogZ among qualifying fits wins."""
    base = _Post(-1000.0, 0.5)
    fits = {"scale": _Post(-900.0, 0.5), "leak": _Post(-960.0, 0.5), "zipper": _Post(-950.0, 0.5)}
    rep = rank_extensions(base, fits, rms={"scale": 0.9, "leak": 0.6, "zipper": 0.71}, base_rms=1.0)
    rows = {r.name: r for r in rep.rows}
    assert not rows["scale"].found and "effect size" in rows["scale"].reason
    assert rows["scale"].rms_gain == pytest.approx(0.1)
    assert rows["leak"].found and rows["zipper"].found is False  # 29 % < 30 %
    assert rep.winner == "leak"
    # exactly at the threshold counts; a missing RMS never does once RMS is being checked
    rep = rank_extensions(base, fits, rms={"scale": 0.7}, base_rms=1.0)
    assert rep.winner == "scale"
    assert not any(r.found for r in rep.rows if r.name != "scale")
    # the threshold is a parameter: 0 turns the rule back into evidence only
    assert (
        rank_extensions(
            base, fits, rms={"scale": 0.9, "leak": 0.6, "zipper": 0.71}, base_rms=1.0, min_rms_gain=0.0
        ).winner
        == "scale"
    )


def test_null_consistent_posteriors():
    from vfcore.diagnose.rank import null_consistent

    names = ("E_body", "leak_mm2")
    assert null_consistent(names, [10.0, 0.05], [1.0, 0.04], "leak")  # piled up at the bound
    assert not null_consistent(names, [10.0, 1.5], [1.0, 0.1], "leak")  # a real leak
    assert null_consistent(names, [10.0, 1.5], [1.0, 0.87], "leak")  # unidentified (~ prior)
    # every parameter that has a null must sit at it
    names = ("E_body", "lr_phase", "lr_amp")
    assert null_consistent(names, [10.0, 0.01, 1.02], [1.0, 0.01, 0.03], "asymmetry")
    assert not null_consistent(names, [10.0, 0.01, 0.7], [1.0, 0.01, 0.03], "asymmetry")
    assert null_consistent(("sep_ratio",), [1.31], [0.02], "sep_ratio")
    assert not null_consistent(("sep_ratio",), [1.15], [0.02], "sep_ratio")
    # a parameter without a null (membrane stiffness) is not tested; the membrane's thickness decides
    assert null_consistent(("E_epith_kpa", "h_epith_mm"), [50.0, 0.004], [50.0, 0.003], "epithelium")
    assert not null_consistent(("E_epith_kpa", "h_epith_mm"), [50.0, 0.05], [50.0, 0.01], "epithelium")
    # an extension without any null would never be
    assert not null_consistent(("E_epith_kpa",), [5.0], [50.0], "epithelium")
    # two modes either side of the null (an integrated lag at equal stiffness): mean +- 2 sd
    # straddles 0, but the likelihood at 0 is far below the best, and that decides
    names = ("E_body", "log2_lr_Q", "lr_lag")
    mean, sd = [10.0, 0.06, 0.004], [1.0, 0.05, 0.07]
    assert null_consistent(names, mean, sd, "lr_stiffness")
    assert not null_consistent(names, mean, sd, "lr_stiffness", drops={"lr_lag": 300.0})
    assert null_consistent(names, mean, sd, "lr_stiffness", drops={"lr_lag": 1.5})
    # the drop only vetoes: a mean far from the null still fails with a small drop
    assert not null_consistent(names, [10.0, 0.06, 0.2], [1.0, 0.05, 0.01], "lr_stiffness", drops={"lr_lag": 1.0})


def test_nested_gate_reads_the_likelihood_drop_at_the_null():
    """The nested check's gate (``by_drop=True``): a phase difference pinned 2.7 sd from zero
    whose null costs only 2.2 nats passes (an asymmetry fit of a concealed recording, whose in-phase form is
    a scale error), one that costs 20 nats does not, and without a measured drop the mean +- 2 sd
    test still applies."""
    from vfcore.diagnose.rank import null_consistent

    names = ("E_body", "E_cover", "p_sub", "lr_phase", "lr_amp")
    mean, sd = [12.64, 545.0, 1656.0, 0.0121, 0.744], [1e-8, 1e-6, 1e-5, 0.0045, 0.006]
    drops = {"lr_phase": 2.18, "lr_amp": 1266.0}
    only = ("lr_phase",)
    assert not null_consistent(names, mean, sd, "asymmetry", only=only, drops=drops)  # 2.7 sd: the sd rule
    assert null_consistent(names, mean, sd, "asymmetry", only=only, drops=drops, by_drop=True)
    assert not null_consistent(names, mean, sd, "asymmetry", only=only, drops={**drops, "lr_phase": 20.0}, by_drop=True)
    assert not null_consistent(names, mean, sd, "asymmetry", only=only, drops={"lr_amp": 1266.0}, by_drop=True)
    assert not null_consistent(names, mean, sd, "asymmetry", only=only, drops={"lr_phase": float("nan")}, by_drop=True)


def test_rank_null_fit_is_not_named_and_raises_the_reference():
    """A refit at its null value that beats the base found a better material mode: it is not
    named, and the other gains are measured against it (evidence and RMS)."""
    base = _Post(-5000.0, 1.0)
    fits = {"sep_ratio": _Post(-1000.0, 1.0), "frame_rate": _Post(-700.0, 1.0), "leak": _Post(-990.0, 1.0)}
    rms = {"sep_ratio": 1.2, "frame_rate": 0.5, "leak": 1.1}
    rep = rank_extensions(base, fits, rms=rms, base_rms=11.9, null={"sep_ratio": True})
    rows = {r.name: r for r in rep.rows}
    assert rep.reference == "sep_ratio" and rep.notes
    assert not rows["sep_ratio"].found and rows["sep_ratio"].delta == pytest.approx(0.0)
    assert rows["leak"].delta == pytest.approx(10.0) and rows["leak"].rms_gain == pytest.approx(1 - 1.1 / 1.2)
    assert not rows["leak"].found  # 8 % against the new reference
    assert rows["frame_rate"].found and rep.winner == "frame_rate"
    assert rows["frame_rate"].rms_gain == pytest.approx(1 - 0.5 / 1.2)
    # a null fit below the base evidence leaves the reference at the base and is not named
    rep = rank_extensions(base, {"leak": _Post(-6000.0, 1.0)}, rms={"leak": 0.1}, base_rms=11.9, null={"leak": True})
    assert rep.reference == "base" and rep.winner is None and rep.rows[0].null_consistent


def test_rank_base_refit_near_the_winner_is_a_reference():
    """A base-model fit re-run near the winner's material mode that explains the data nearly as
    well takes the winner's gain away (evidence and RMS are measured against it)."""
    base = _Post(-25000.0, 1.0)
    fits = {"leak": _Post(-650.0, 1.0), "frame_rate": _Post(-840.0, 1.0)}
    rms = {"leak": 1.34, "frame_rate": 1.59}
    assert rank_extensions(base, fits, rms=rms, base_rms=11.9).winner == "leak"
    rep = rank_extensions(base, fits, rms=rms, base_rms=11.9, references={"base near leak": (-700.0, 1.0, 1.5)})
    assert rep.reference == "base near leak" and rep.winner is None and rep.notes
    rows = {r.name: r for r in rep.rows}
    assert rows["leak"].delta == pytest.approx(50.0) and "effect size" in rows["leak"].reason
    # a lower bound below the base evidence changes nothing
    rep = rank_extensions(base, fits, rms=rms, base_rms=11.9, references={"base near leak": (-26000.0, 1.0, 0.1)})
    assert rep.reference == "base" and rep.winner == "leak"


def test_rank_missing_se_never_found():
    rep = rank_extensions((-100.0, math.nan), {"leak": (-50.0, 0.1)})
    assert rep.winner is None and rep.notes


def test_residual_removed_by_leak_extension():
    base = gaw_like()
    obs = base + 1.2
    before = locate(obs, base, FPS)
    after = locate(obs, get("leak").apply(base, {"leak_mm2": 1.2, "chink_fraction": 0.0}, fps=FPS), FPS)
    assert residual_removed(before, after) == pytest.approx(1.0)
    worse = locate(obs, base - 1.0, FPS)
    assert residual_removed(before, worse) < 0


def _posterior(pred_gaws, obs, logz, se, names=("E_body",)):
    from vfcore.inference import Evaluation, Posterior

    k = pred_gaws.shape[0]
    ev = Evaluation(loglik=np.zeros(k), ok=np.ones(k, bool), gaw=pred_gaws.astype(np.float32))
    return Posterior.from_weighted(
        names,
        np.arange(k * len(names), dtype=float).reshape(k, len(names)),
        np.zeros(k),
        rng=np.random.default_rng(0),
        log_evidence=logz,
        log_evidence_se=se,
        check=False,
        predictive=ev,
        obs_gaw=obs,
        fps=FPS,
    )


def test_compare_fits_from_posteriors():
    from vfcore.diagnose import compare_fits, from_posterior

    base = gaw_like()
    obs = np.maximum(base, 1.0)
    p0 = _posterior(np.tile(base, (20, 1)), obs, -200.0, 0.3)
    p1 = _posterior(
        np.tile(np.maximum(base, 1.0), (20, 1)), obs, -150.0, 0.3, names=("E_body", "leak_mm2", "chink_fraction")
    )
    p1.samples[:, 1] = 1.0 + 0.01 * np.arange(20)  # a leak of ~1 mm^2, far from its null (0)
    p1.samples[:, 2] = 0.05 * np.arange(20)  # chink fraction unidentified (it has no null)
    rep, pv = from_posterior(p0)
    assert rep.dominant_phase == "closed"
    assert pv["min_area_mm2"].p_upper == 0.0 and pv["glottal_gap_index"].p_two_sided == 0.0
    r = compare_fits(p0, {"leak": p1})
    assert r.winner == "leak" and r.rows[0].n_extra == 2
    assert r.rows[0].residual_removed == pytest.approx(1.0, abs=1e-6)
    assert r.rows[0].rms_gain == pytest.approx(1.0, abs=1e-6) and not r.rows[0].null_consistent
    # the same fit with its leak at the null value (0) is a better base fit, not a finding
    p1.samples[:, 1] = 0.001 * np.arange(20)
    r = compare_fits(p0, {"leak": p1})
    assert r.winner is None and r.rows[0].null_consistent and r.reference == "leak"


def test_between_run_error_from_independent_base_runs():
    """Two runs of the same model whose evidences differ by far more than their reported errors
    give the unexplained spread as an additive error; runs that agree within their errors give 0."""
    from vfcore.diagnose.baseline import between_run_sd

    tau = between_run_sd([_Post(-446.0, 0.6), _Post(-440.7, 0.5)])
    assert tau == pytest.approx(math.sqrt(5.3**2 / 2 - (0.36 + 0.25) / 2))
    assert between_run_sd([_Post(-446.0, 0.6), _Post(-446.2, 0.5)]) == 0.0
    assert between_run_sd([_Post(-446.0, 0.6)]) == 0.0
    assert between_run_sd([_Post(-446.0, math.nan), _Post(-440.0, 0.5)]) == 0.0
    # a concealed case with base runs 1,027 nats apart: a 3,515-nat gain still clears 3 combined errors
    tau = between_run_sd([_Post(-5121.0, 0.3), _Post(-4093.7, 0.6)])
    se = math.hypot(math.hypot(0.6, tau), math.hypot(1.0, tau))
    assert 3 * se < 3515.4 < 5 * se


def test_base_fit_escalates_when_runs_disagree(monkeypatch):
    """Base runs whose log-evidences differ beyond their errors trigger more particles; agreeing
    runs do not. A fake sampler: evidence depends on the seed at 40 particles (mode hopping) and
    is stable at 80."""
    import sys
    from types import SimpleNamespace

    from vfcore.diagnose.baseline import base_fit

    smc_mod = sys.modules["vfcore.inference.smc"]  # the package re-exports the function under the same name
    calls = []

    def fake_smc(problem, n_particles, seed, **kw):  # runs told apart by their order, not their seeds
        k = len(calls)
        calls.append((n_particles, seed))
        z = (-100.0 - 500.0 * (k % 2)) if n_particles == 40 else -90.0 - 0.1 * (k % 3)
        return SimpleNamespace(log_evidence=z, log_evidence_se=1.0, n_simulations=10 * n_particles)

    def together(fake):  # runs made together: each as alone (test_smc_many)
        return lambda problem, jobs, **kw: [fake(problem, n, s) for n, s in jobs]

    monkeypatch.setattr(smc_mod, "smc", fake_smc)
    monkeypatch.setattr(smc_mod, "smc_many", together(fake_smc))
    base, tau, factor, n, notes = base_fit(None, n_particles=40, base_runs=2, seed=0)
    assert factor == 2 and [c[0] for c in calls] == [40, 40, 80, 80]
    assert len({c[1] for c in calls}) == 4  # every run its own seed
    assert base.log_evidence > -91 and tau < 1.0 and n == 10 * (40 + 40 + 80 + 80)
    assert any("disagree" in s for s in notes)

    calls.clear()

    def agreeing(problem, n_particles, seed, **kw):
        k = len(calls)
        calls.append(seed)
        return SimpleNamespace(log_evidence=-100.0 + 0.5 * (k % 2), log_evidence_se=1.0, n_simulations=5)

    monkeypatch.setattr(smc_mod, "smc", agreeing)
    monkeypatch.setattr(smc_mod, "smc_many", together(agreeing))
    base, tau, factor, n, notes = base_fit(None, n_particles=40, base_runs=2, seed=0)
    assert factor == 1 and len(calls) == 2 and tau == 0.0 and base.log_evidence == -99.5
    base, tau, factor, n, notes = base_fit(None, n_particles=40, base_runs=2, seed=0, escalate_tau=None)
    assert factor == 1


def test_an_escalation_doubles_the_later_fits_particles_unless_told_not_to(monkeypatch):
    """The escalation factor carries into every later fit (``st.refit_n``) by default; with
    ``escalate_refits=False`` only the base runs are escalated. The base runs themselves are the same
    either way."""
    from types import SimpleNamespace

    import vfcore.diagnose.baseline as B
    from vfcore.diagnose.options import DiagnoseOptions
    from vfcore.diagnose.state import DiagnosisState, Run

    def fake_base_fit(problem, n_particles, runs_out, **kw):
        runs_out.extend([(-100.0, 1.0), (-600.0, 1.0)])
        return SimpleNamespace(log_evidence=-90.0), 0.5, 2, 1234, ["base runs disagree"]

    monkeypatch.setattr(B, "base_fit", fake_base_fit)
    monkeypatch.setattr(DiagnosisState, "summary", lambda self, post: {"predictive_noise_sd": 0.0})
    seen = {}
    for flag in (True, False):
        o = DiagnoseOptions(free_material=False, escalate_refits=flag)
        st = DiagnosisState(
            problem=SimpleNamespace(noise="fixed", sigma_e=1.0), base=None, refit_n=o.refit_n, candidates=[]
        )
        B.fit_base(Run.start(o, map, None), st)
        seen[flag] = (st.refit_n, st.n_simulations, st.base.log_evidence)
    assert seen[True] == (48, 1234, -90.0) and seen[False] == (24, 1234, -90.0)


def test_promote_local_names_a_gain_swamped_only_by_the_between_run_error():
    from vfcore.diagnose.amend import promote_local

    # a 6,585-nat gain with 82 % RMS gain, but base runs 1,760 nats apart: not found globally
    tau = 1760.0
    r = rank_extensions(
        (-7175.4, math.hypot(0.5, tau)),
        {"epithelium": (-590.0, math.hypot(1.0, tau)), "leak": (-6607.0, math.hypot(1.0, tau))},
        rms={"epithelium": 1.1, "leak": 5.9},
        base_rms=6.17,
        null={},
    )
    assert r.winner is None
    row = next(x for x in r.rows if x.name == "epithelium")
    assert row.reason.startswith("evidence") and row.rms_gain > 0.8
    p = promote_local(r, "epithelium", 5000.0, 1.5, tau)
    assert p.winner == "epithelium" and p.physics == "epithelium" and "local comparison" in p.notes[-1]
    # the verdict gives the comparison that named it, and the global gain with its swamping error beside it
    row = next(x for x in p.rows if x.name == "epithelium")
    assert (
        "named on the local comparison: dlogZ = 5000.00 +- 1.50" in p.verdict
        and f"{row.delta:.2f} +- {row.delta_se:.2f} against the reference" in p.verdict
    )
    assert "local comparison" not in r.verdict
    # a later rule that names another entry drops the local basis with it
    from vfcore.diagnose.amend import prefer_nested

    q = prefer_nested(p, "leak", "epithelium", "nested")
    assert q.winner == "leak" and q.local is None and "local comparison" not in q.verdict
    assert next(x for x in p.rows if x.name == "epithelium").found
    assert not next(x for x in p.rows if x.name == "leak").found
    assert r.winner is None  # the original report is unchanged


def test_rivals_within_the_errors_are_reported_not_named():
    # winner 3,106 +- 55, runner-up of another physics 147 nats lower: 147 < 3 * 78 -> a rival
    r = rank_extensions(
        (-5000.0, 1.0),
        {
            "subglottal": (-1894.0, 55.0),
            "epithelium": (-2041.0, 55.0),
            "leak": (-4000.0, 55.0),
            "lr_stiffness": (-1950.0, 55.0),
            "asymmetry": (-1960.0, 55.0),
        },
        rms={"subglottal": 1.0, "epithelium": 1.2, "leak": 3.0, "lr_stiffness": 1.3, "asymmetry": 1.3},
        base_rms=4.0,
        null={},
    )
    assert r.winner == "subglottal"
    names = [x[0] for x in r.rivals]
    assert names == ["asymmetry", "epithelium"]  # one entry per family, leak is far below
    assert "not distinguishable from asymmetry" in r.verdict and "epithelium" in r.verdict
    far = rank_extensions(
        (-5000.0, 1.0),
        {"subglottal": (-1894.0, 5.0), "epithelium": (-2041.0, 5.0)},
        rms={"subglottal": 1.0, "epithelium": 1.2},
        base_rms=4.0,
        null={},
    )
    assert far.rivals == [] and "distinguishable" not in far.verdict


def test_confusable_entries_are_always_rivals():
    # zipper vs the phase/amplitude asymmetry: 9 nats apart with 1.4-nat errors (a concealed zipper case)
    r = rank_extensions(
        (-3000.0, 1.0),
        {"asymmetry": (-2560.7, 1.0), "zipper": (-2570.0, 1.0), "leak": (-2945.0, 1.0)},
        rms={"asymmetry": 1.65, "zipper": 1.63, "leak": 3.1},
        base_rms=3.25,
        null={},
    )
    assert r.winner == "asymmetry" and [x[0] for x in r.rivals] == ["zipper"]
    assert r.rivals[0][1] > 3 * r.rivals[0][2]  # beyond the errors, listed anyway
    # not confusable: the same gap between sep_ratio and epithelium is not a rivalry
    r2 = rank_extensions(
        (-3000.0, 1.0),
        {"sep_ratio": (-2560.7, 1.0), "epithelium": (-2570.0, 1.0)},
        rms={"sep_ratio": 1.65, "epithelium": 1.63},
        base_rms=3.25,
        null={},
    )
    assert r2.rivals == []


def test_in_phase_asymmetry_is_a_scale_error_and_the_simpler_entry_is_preferred():
    """The asymmetry entry nests the scale entry: at zero phase difference its observation is
    A (1 + lr_amp) / 2 exactly; prefer_nested names the simpler entry with a note."""
    from vfcore.diagnose.amend import prefer_nested
    from vfcore.diagnose.extensions import get
    from vfcore.diagnose.fit import observe_extended

    assert get("asymmetry").nests == (("scale", ("lr_phase",)),)
    t = np.arange(6000) / 20000.0
    y = 8.0 * np.maximum(np.sin(2 * np.pi * 120.0 * t), 0.0)
    a = observe_extended("asymmetry", y, 2000.0, {"lr_phase": 0.0, "lr_amp": 1.27})
    np.testing.assert_allclose(a, observe_extended("scale", y, 2000.0, {"scale": 1.135}), atol=1e-12)
    # a concealed scale case: asymmetry at lr_phase 0.009 +- 0.005 named; scale refitted in its mode
    r = rank_extensions(
        (-565.4, 0.6),
        {"asymmetry": (-395.8, 1.0), "scale": (-397.0, 1.0), "frame_rate": (-410.9, 1.0)},
        rms={"asymmetry": 0.512, "scale": 0.515, "frame_rate": 0.605},
        base_rms=1.102,
        null={},
    )
    assert r.winner == "asymmetry"
    p = prefer_nested(r, "scale", "asymmetry", "scale: named instead of asymmetry")
    assert p.winner == "scale" and p.physics == "scale" and p.notes[-1].startswith("scale: named instead")
    assert "not distinguishable from asymmetry" in p.verdict
    assert r.winner == "asymmetry"  # the original report is unchanged


def test_best_of_base_names_a_gain_far_above_every_base_fit_that_the_run_scatter_swamped():
    """A concealed scale error on an irregular base: base runs at -2,506,
    -2,378, -2,482 and -1,904 nats (between-run error 409), the scale refit at -644 with its RMS
    59 % lower. With the between-run error in quadrature the 1,260-nat gain is 2.2 se and not
    named; against the best of all base fits by their own errors it is."""
    from vfcore.diagnose.rank import rank_best_of_base

    runs = [(-2506.1, 0.5), (-2378.2, 0.7), (-2481.7, 0.5), (-1903.7, 0.4)]
    tau = 408.75
    fits = {"scale": (-644.0, 0.44), "asymmetry": (-870.8, 0.5), "leak": (-1880.5, 0.5)}
    rms = {"scale": 1.117, "asymmetry": 1.518, "leak": 2.71}
    shipped = rank_extensions(
        (-1903.7, math.hypot(0.4, tau)),
        {k: (z, math.hypot(s, tau)) for k, (z, s) in fits.items()},
        rms=rms,
        base_rms=2.746,
    )
    assert shipped.winner is None and "evidence" in shipped.rows[0].reason
    r = rank_best_of_base((-1903.7, 0.4), fits, base_runs=runs, rms=rms, base_rms=2.746)
    assert r.winner == "scale" and r.reference == "base"
    w = r.rows[0]
    assert abs(w.delta - 1259.7) < 0.1 and w.delta_se < 1.0 and abs(w.rms_gain - (1 - 1.117 / 2.746)) < 1e-12
    # the base refitted around scale's material mode, as good as the scale fit: nothing is named
    r = rank_best_of_base(
        (-1903.7, 0.4), fits, base_runs=runs, rms=rms, base_rms=2.746, mode_checks={"scale": (-646.0, 0.5, 1.13)}
    )
    assert r.winner is None and r.reference == "base near scale"
    # a base run above the kept one (never from base_fit, which keeps the largest) becomes the reference
    r = rank_best_of_base((-1903.7, 0.4), fits, base_runs=runs + [(-600.0, 0.5)], rms=rms, base_rms=2.746)
    assert r.winner is None and r.reference == "base run (4)"


def test_best_of_base_keeps_the_effect_size_against_a_null_consistent_reference():
    """A concealed control with an irregular base: the asymmetry refit is 394 nats
    above every base-model fit and 40 % lower in RMS than the base, but only 26 % lower than the
    reference (the exposure refit at its null value, a better base-model fit). Not named."""
    from vfcore.diagnose.rank import rank_best_of_base

    fits = {"asymmetry": (-1000.0, 0.7), "exposure": (-1394.0, 0.5)}
    rms = {"asymmetry": 0.60, "exposure": 0.81}
    r = rank_best_of_base(
        (-1500.0, 0.5),
        fits,
        base_runs=[(-1500.0, 0.5), (-2300.0, 0.6)],
        rms=rms,
        base_rms=1.0,
        null={"asymmetry": False, "exposure": True},
    )
    assert r.reference == "exposure" and r.winner is None
    row = next(x for x in r.rows if x.name == "asymmetry")
    assert abs(row.delta - 394.0) < 1e-9 and "effect size" in row.reason
    # the same fits with the exposure refit off its null: it is no reference, and asymmetry is named
    r = rank_best_of_base(
        (-1500.0, 0.5),
        fits,
        base_runs=[(-1500.0, 0.5), (-2300.0, 0.6)],
        rms=rms,
        base_rms=1.0,
        null={"asymmetry": False, "exposure": False},
    )
    assert r.winner == "asymmetry"


def test_strip_sum_equals_interpolated_delays_with_held_ends():
    """The zipper's fused kernel: sum_k w_k y(i - d_k) equals np.interp of each delayed
    copy (ends held) for delays inside, beyond and exactly at whole samples, to rounding."""
    from vfcore.diagnose._kernels import strip_sum

    rng = np.random.default_rng(4)
    y = np.cumsum(rng.standard_normal(500))
    i = np.arange(y.size, dtype=float)
    for delays in (
        rng.uniform(-3, 3, 24),
        rng.uniform(-700, 700, 24),
        np.round(rng.uniform(-50, 50, 24)),
        np.array([0.0, 499.0, -499.0, 0.5]),
    ):
        w = rng.random(delays.size)
        ref = sum(wk * np.interp(i - dk, i, y) for dk, wk in zip(delays, w))
        assert np.max(np.abs(strip_sum(y, delays, w) - ref)) < 1e-12 * np.max(np.abs(ref))
