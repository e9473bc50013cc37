"""Material first (vfcore.diagnose.material) and the "no fit" verdict (vfcore.diagnose.adequacy)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vfcore.config import SimConfig
from vfcore.diagnose.adequacy import NO_FIT, check_fit
from vfcore.diagnose.material import freed_problem, judge, pinned, prior_set_of
from vfcore.forward import simulate
from vfcore.inference import Prior
from vfcore.inference.prior import HUMAN_BOUNDS, TABLE2_BOUNDS
from vfcore.inference.problem import Problem
from vfcore.params import PARAM_NAMES, TABLE3
from vfcore.result import HR_OVERSAMPLE

FPS = 2000.0
CFG = SimConfig(mesh="coarse", dt=1e-4, duration=0.35, discard=0.15)


@pytest.fixture(scope="module")
def clean():
    r = simulate(TABLE3, CFG)
    return np.asarray(r.gaw_hr[37::HR_OVERSAMPLE][:200])


def _problem(y, estimate, fixed=None, measurements=None, prior_set="paper"):
    fx = {n: getattr(TABLE3, n) for n in PARAM_NAMES if n not in estimate}
    fx.update(fixed or {})
    return Problem(y, FPS, Prior.default(fixed=fx, prior_set=prior_set), config=CFG, measurements=measurements or {})


def test_pinned_are_the_scaled_parameters_held_at_table3_but_the_anchor(clean):
    # what the command line builds: every parameter not estimated fixed at its Table 3 value
    assert pinned(_problem(clean, ("E_body", "E_cover", "p_sub"))) == ["E_lig", "eta"]
    assert pinned(_problem(clean, ("E_body", "E_cover", "E_lig", "p_sub", "eta"))) == []
    # a value the user chose is not pinned, and it anchors the scale: the density is then free too
    assert pinned(_problem(clean, ("E_body", "E_cover"), fixed={"p_sub": 1000.0})) == ["E_lig", "rho", "eta"]
    # a measurement anchors the scale as well
    assert pinned(_problem(clean, ("E_body", "E_cover", "p_sub", "rho"), measurements={"rho": (1050.0, 20.0)})) == [
        "E_lig",
        "eta",
    ]
    # x0 is geometric, not one of the scaled six: never freed
    assert "x0" not in pinned(_problem(clean, ("E_cover",)))


def test_freed_problem_takes_the_bounds_of_its_prior_set(clean):
    pb = _problem(clean, ("E_body", "E_cover", "p_sub"))
    assert prior_set_of(pb.prior) == "paper"
    free = freed_problem(pb, ["E_lig", "eta"])
    assert set(free.prior.names) == {"E_body", "E_cover", "E_lig", "p_sub", "eta"}
    assert free.prior.bounds["E_lig"] == TABLE2_BOUNDS["E_lig"] and free.prior.fixed["rho"] == TABLE3.rho
    human = _problem(clean, ("E_body", "E_cover", "p_sub"), prior_set="human")
    assert prior_set_of(human.prior) == "human"
    assert freed_problem(human, ["E_lig"]).prior.bounds["E_lig"] == HUMAN_BOUNDS["E_lig"]


def test_judge_applies_the_naming_rule():
    pin = {"log_evidence": -1000.0, "log_evidence_se": 1.0, "residual_rms": 2.0}
    assert judge(pin, {"log_evidence": -900.0, "log_evidence_se": 1.0, "residual_rms": 1.0})["found"]
    small = judge(pin, {"log_evidence": -900.0, "log_evidence_se": 1.0, "residual_rms": 1.5})
    assert not small["found"] and small["reason"].startswith("effect size")
    noisy = judge(pin, {"log_evidence": -990.0, "log_evidence_se": 5.0, "residual_rms": 1.0})
    assert not noisy["found"] and noisy["reason"].startswith("evidence")
    assert not judge(pin, {"log_evidence": math.nan, "log_evidence_se": 1.0, "residual_rms": 1.0})["found"]


def test_check_fit_reads_the_smallest_residual():
    fits = {
        "base": {
            "residual_rms": 7.0,
            "predictive_noise_sd": 0.5,
            "dominant_phase": "closed",
            "pvalues": {"gap_index": 0.0, "f0": 0.4},
        },
        "leak": {
            "residual_rms": 4.6,
            "predictive_noise_sd": 0.46,
            "dominant_phase": "opening",
            "pvalues": {"gap_index": 0.3, "SQ": 0.01, "jitter": float("nan")},
        },
    }
    c = check_fit(fits)
    assert c.best == "leak" and c.ratio == pytest.approx(10.0) and not c.fits
    assert c.measures == ["SQ"]
    s = c.sentence("leak (dlogZ = 20)")
    assert s.startswith(NO_FIT) and "opening phase" in s and "SQ" in s and "leak (dlogZ = 20)" in s
    assert check_fit({"base": {**fits["base"], "residual_rms": 0.9}}).fits


@pytest.mark.slow
def test_a_recording_with_wrong_fixed_parameters_is_explained_by_freeing_them(clean):
    """Known truth: the recording is the model itself with eta far from Table 3 (6.5 against 3.079
    Poise) and nothing left out. The pinned base (eta at Table 3) cannot reproduce it; the
    diagnosis must say the fixed parameters were wrong, name no catalogue entry, and find the fit."""
    from vfcore.diagnose.pipeline import diagnose
    from vfcore.params import Params

    truth = Params(**{**TABLE3.as_dict(), "eta": 6.5, "E_cover": 520.0})
    r = simulate(truth, CFG)
    y = np.asarray(r.gaw_hr[37::HR_OVERSAMPLE][:200]) + 0.2 * np.random.default_rng(5).standard_normal(200)
    pb = _problem(y, ("E_body", "E_cover", "p_sub"))
    assert pinned(pb) == ["E_lig", "eta"]
    rep = diagnose(
        pb,
        n_particles=16,
        refit_particles=None,
        seed=1,
        candidates=["scale"],
        base_runs=1,
        continuation=False,
        regularity_check=False,
        mode_checks=0,
        local_check=False,
    )
    m = rep.material
    assert m is not None and m["found"], m
    assert m["kept"] == "free" and m["rms_gain"] >= 0.3
    eta = m["free"]["params"]["eta"]
    assert abs(eta["mean"] - 6.5) < max(3 * eta["sd"], 1.0), eta
    assert rep.winner is None and "the fixed parameters were wrong" in rep.verdict
    assert rep.fits, rep.fit_check


def _one_parameter(y):
    return Problem(
        y, FPS, Prior.default(fixed={n: getattr(TABLE3, n) for n in PARAM_NAMES if n != "E_cover"}), config=CFG
    )


SMALL = dict(
    free_material=False,
    continuation=False,
    continuation_entries=None,
    refit_particles=None,
    n_particles=12,
    seed=2,
    base_runs=1,
    regularity_check=False,
    mode_checks=0,
    local_check=False,
    candidates=["scale", "leak"],
)


def test_a_base_fit_at_the_noise_stops_before_the_catalogue(clean):
    """A recording of the model itself: the base fit leaves about the noise, no entry could lower
    its RMS by 30 %, so nothing is screened or refitted and nothing is named."""
    from vfcore.diagnose.pipeline import diagnose

    y = clean + 0.4 * np.random.default_rng(3).standard_normal(clean.size)
    rep = diagnose(_one_parameter(y), **SMALL)
    assert rep.before["residual_rms"] < 1.43 * rep.before["predictive_noise_sd"]
    assert rep.screening == {} and rep.refits == {} and rep.winner is None
    assert rep.verdict == "no missing physics found" and rep.fits
    assert any("none was screened" in n for n in rep.notes)


@pytest.mark.slow
def test_an_effect_outside_the_catalogue_is_not_named(clean):
    """Alternate cycles 30 % larger and smaller (diplophonia, no catalogue entry): neither a scale
    error nor a leak reproduces it, the best fit stays far above the noise, and the verdict says
    the model does not fit instead of naming the entry that absorbed most."""
    from vfcore.diagnose.pipeline import diagnose

    r = simulate(TABLE3, CFG)
    idx = np.searchsorted(
        np.asarray(r.cycles.t_start), (37 + HR_OVERSAMPLE * np.arange(200)) / (FPS * HR_OVERSAMPLE), side="right"
    )
    y = clean * np.where(idx % 2 == 0, 1.3, 0.7) + 0.3 * np.random.default_rng(4).standard_normal(clean.size)
    rep = diagnose(_one_parameter(y), **SMALL)
    assert not rep.fits and rep.winner is None
    assert rep.verdict.startswith(NO_FIT) and rep.fit_check.ratio > 2.0
    assert rep.to_dict()["winner"] is None and rep.to_dict()["fit_check"]["fits"] is False
