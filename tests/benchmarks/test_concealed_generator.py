"""Concealed-effect benchmark generator (benchmarks/concealed/generate.py)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks.concealed import absorb as A  # noqa: E402
from benchmarks.concealed import generate as G  # noqa: E402
from vfcore import TABLE3, Params, simulate  # noqa: E402

CFG = G.BASE_CONFIG
L = CFG.length_mm


@pytest.fixture(scope="module")
def base():
    r = simulate(TABLE3, CFG)
    assert r.ok and G.oscillates(r.gaw, r.fps)
    return r


def _window(base, offset=77.3):
    t_hr = G.hr_times(base)
    t = G.frame_times(G.N_OBS, offset, CFG.fps)
    return t_hr, t, G.sample_hr(np.asarray(base.gaw_hr), t_hr, t)


def test_generator_does_not_import_diagnose():
    modules = sorted(Path(G.__file__).parent.glob("*.py"))
    assert {m.name for m in modules} >= {"generate.py", "absorb.py", "mechanisms.py", "config.py"}
    for m in modules:
        imports = "".join(ln for ln in m.read_text().splitlines() if ln.lstrip().startswith(("import", "from")))
        assert "diagnose" not in imports, m.name


def test_suite_covers_every_label():
    labels = G.suite_labels()
    avail = G.forward_extensions_available()
    for lab in G.EFFECTS + ("control",):
        if lab in avail and not avail[lab]:
            continue
        assert labels.count(lab) >= (4 if lab == "control" else 1), lab
    for lab in G.PHYSICAL:
        if avail.get(lab, True):
            assert labels.count(lab) >= 2, lab
    assert sum(lab != "control" for lab in labels) >= 16 - 2 * (not all(avail.values()))


def test_full_suite_covers_outside_effects_pairs_and_controls():
    labels = G.suite_labels(G.SUITE_COUNTS_FULL)
    assert set(labels) == set(G.LABELS)
    assert labels.count("control") >= 4
    for pair in G.PAIRS:
        first, second = pair.split("+")
        assert first in G.FORWARD and second in G.EFFECTS and second not in G.FORWARD


def test_full_truth_draws_five_combinations_at_the_anchor():
    from benchmarks.concealed.config import FULL_BOUNDS, SCALE_ANCHOR

    rng = np.random.default_rng(0)
    draws = [G.draw_truth(rng, "full") for _ in range(200)]
    for name, (lo, hi) in FULL_BOUNDS.items():
        v = np.array([getattr(d, name) for d in draws])
        assert lo <= v.min() and v.max() <= hi and v.max() - v.min() > 0.8 * (hi - lo), name
    assert all(d.rho == SCALE_ANCHOR["rho"] and d.x0 == TABLE3.x0 for d in draws)
    # the three-parameter set keeps E_lig, rho and eta at Table 3 (its suites are reproducible)
    three = G.draw_truth(np.random.default_rng(0))
    assert (three.E_lig, three.rho, three.eta) == (TABLE3.E_lig, TABLE3.rho, TABLE3.eta)


def test_public_files_of_a_full_suite_name_the_five_and_the_anchor(tmp_path):
    cases = G.generate_suite(2, counts={"control": 1}, presence=False, material="full")
    G.write_suite(cases, tmp_path, 2, material="full")
    pub = json.loads((tmp_path / "cases.json").read_text())
    assert pub["material"] == "full" and set(pub["estimated"]) == {"E_body", "E_cover", "E_lig", "p_sub", "eta"}
    assert pub["fixed"] == {"rho": 1051.0, "x0": TABLE3.x0}


def test_outside_effects_have_their_shapes(base):
    t_hr, t, a = _window(base)
    rng = np.random.default_rng(1)
    clean, eff = G.apply_effect("diplophonia", base, TABLE3, 77.3, rng)
    k = G._cycle_index(base, t)
    ratio = clean[a > 1.0] / a[a > 1.0]
    gains = {1.0 + eff["depth"], 1.0 - eff["depth"]}
    assert all(min(abs(r - g) for g in gains) < 1e-12 for r in ratio)  # alternate cycles, two gains
    assert len(set(k % 2)) == 2
    clean, eff = G.apply_effect("gamma", base, TABLE3, 77.3, np.random.default_rng(2))
    assert np.all(np.diff(clean[np.argsort(a)]) >= -1e-12)  # a monotone read-out of the area
    i = np.argmin(abs(a - eff["ref_mm2"]))
    assert clean[i] == pytest.approx(a[i] * (a[i] / eff["ref_mm2"]) ** (eff["gamma"] - 1.0), rel=1e-12)
    clean, eff = G.apply_effect("tremor", base, TABLE3, 77.3, np.random.default_rng(3))
    env = clean / np.where(a > 1.0, a, np.nan)
    assert np.nanmax(env) <= 1.0 + eff["depth"] + 1e-12 and np.nanmin(env) >= 1.0 - eff["depth"] - 1e-12


def test_leak_shape_power_moves_the_gap_posteriorly():
    blunt = G.gap_profile(2.0, 0.5, L, power=0.5)
    slit = G.gap_profile(2.0, 0.5, L, power=2.0)
    dy = L / blunt.size
    assert blunt.sum() * dy == pytest.approx(2.0) and slit.sum() * dy == pytest.approx(2.0)
    assert slit[-1] > G.gap_profile(2.0, 0.5, L)[-1] > blunt[-1]


SMALL = {"leak": 1, "sep_ratio": 1, "control": 1}


@pytest.mark.slow  # a whole small suite generated twice (about a minute on 2 cores)
def test_determinism_and_public_files(tmp_path):
    a = G.generate_suite(5, counts=SMALL)
    b = G.generate_suite(5, counts=SMALL)
    c = G.generate_suite(6, counts=SMALL, presence=False)
    assert [x.label for x in a] == [x.label for x in b]
    for x, y in zip(a, b):
        assert np.array_equal(x.gaw, y.gaw) and np.array_equal(x.clean, y.clean)
        assert x.truth == y.truth and x.effect == y.effect and x.offset_frames == y.offset_frames
    assert not any(np.array_equal(x.gaw, y.gaw) for x in a for y in c)
    assert sorted(x.label for x in a) == sorted(SMALL)

    G.write_suite(a, tmp_path, seed=5)
    text = (tmp_path / "cases.json").read_text()
    pub = json.loads(text)
    for entry in pub["cases"]:
        assert set(entry) == {"id", "file", "fps", "n_frames"}
        assert entry["n_frames"] == G.N_OBS and entry["fps"] == CFG.fps
        col = np.loadtxt(tmp_path / entry["file"], skiprows=1)
        assert col.shape == (G.N_OBS,)
        assert (tmp_path / entry["file"]).read_text().splitlines()[0] == "area_mm2"
    low = text.lower()
    for word in G.LABELS + ("effect", "label", "sigma", "truth", "offset", "chink", "lag"):
        assert word not in low, word
    hidden = json.loads((tmp_path / "truth.json").read_text())
    for x in a:
        h = hidden["cases"][x.id]
        assert h["label"] == x.label and h["sigma_mm2"] == x.sigma
        assert np.allclose(h["clean"], x.clean, atol=1e-12)
        obs = np.loadtxt(tmp_path / f"case_{x.id}.csv", skiprows=1)
        assert np.allclose(obs, x.gaw, atol=1e-6)
    npz = np.load(tmp_path / "truth.npz")
    assert np.array_equal(npz[f"noisy_{a[0].id}"], a[0].gaw)


def test_control_is_base_window_plus_noise():
    c = G.make_case("c", "control", np.random.SeedSequence(11))
    assert c.effect == {} and G.SIGMA_RANGE[0] <= c.sigma <= G.SIGMA_RANGE[1]
    for k, (lo, hi) in G.TRUTH_BOUNDS.items():
        assert lo <= c.truth[k] <= hi
    r = simulate(Params(**c.truth), CFG)
    t = G.frame_times(G.N_OBS, c.offset_frames, CFG.fps)
    direct = np.interp(t, np.arange(r.gaw_hr.size) / (CFG.fps * 10), r.gaw_hr)
    assert np.max(np.abs(c.clean - direct)) < 1e-9
    assert np.array_equal(c.clean, c.base)
    res = c.gaw - c.clean
    assert 0.8 * c.sigma < res.std() < 1.2 * c.sigma and abs(res.mean()) < 4 * c.sigma / np.sqrt(G.N_OBS)
    # an integer offset reproduces the camera-rate GAW itself
    t_int = G.frame_times(G.N_OBS, 100, CFG.fps)
    assert np.allclose(G.sample_hr(r.gaw_hr, G.hr_times(r), t_int), r.gaw[100 : 100 + G.N_OBS], atol=1e-9)


def test_leak_identity_and_floor(base):
    t_hr, t, a = _window(base)
    w = a / L
    assert np.allclose(G.leak_area(w, np.zeros(G.N_Y), np.ones(G.N_Y)), a, rtol=1e-12, atol=1e-12)
    g = G.gap_profile(2.0, 0.6, L)
    assert np.isclose(g.sum() * L / G.N_Y, 2.0) and g[0] == 0 and np.argmax(g) == G.N_Y - 1
    la = G.leak_area(w, g)
    assert np.all(la >= a - 1e-12) and np.all(la >= 2.0 - 1e-9)
    closed = a < 0.05
    assert closed.any() and np.allclose(la[closed], 2.0 + 0 * la[closed], atol=0.05)
    # not an additive constant: at the peak the chink is (partly) hidden by the open membranous glottis
    assert la.max() - a.max() < 1.0


def test_zipper_identity(base):
    t_hr, t, a = _window(base)
    z = G.zipper_area(np.asarray(base.gaw_hr) / L, t_hr, t, 0.0, 2.0, 0.0, L)
    assert np.max(np.abs(z - a)) < 1e-9
    z2 = G.zipper_area(np.asarray(base.gaw_hr) / L, t_hr, t, 0.2 / base.f0, 2.0, 1.0, L)
    assert np.sqrt(np.mean((z2 - a) ** 2)) > 0.3


def test_asymmetry_identity(base):
    t_hr, t, a = _window(base)
    twin = simulate(TABLE3, CFG)  # a separate but identical right fold
    tc = t[G.N_OBS // 2]
    assert np.max(np.abs(G.asymmetric_area(base, twin, t, 0.0, tc) - a)) < 1e-9
    assert np.max(np.abs(G.asymmetric_area(base, base, t, 0.0, tc) - a)) < 1e-9
    lagged = G.asymmetric_area(base, twin, t, 0.15, tc)
    assert np.sqrt(np.mean((lagged - a) ** 2)) > 0.3 and lagged.min() >= 0


def test_camera_operators(base):
    t_hr, t, a = _window(base)
    # boxcar: exact on a linear signal, and the mean of a sine is scaled by sinc(f tau)
    lin = 3.0 + 2.0 * t_hr
    assert np.allclose(G.boxcar_average(lin, t_hr, t, 0.8 / CFG.fps), 3.0 + 2.0 * t, atol=1e-12)
    f = 150.0
    s_hr = np.sin(2 * np.pi * f * t_hr)
    tau = 1.0 / CFG.fps
    got = G.boxcar_average(s_hr, t_hr, t, tau)
    assert np.allclose(got, np.sinc(f * tau) * np.sin(2 * np.pi * f * t), atol=2e-3)
    assert np.array_equal(G.boxcar_average(a, t, t[5:-5], 0.0), a[5:-5])
    # frame rate: true interval 1/(r fps)
    ft = G.frame_times(10, 3.5, CFG.fps, 1.05)
    assert np.allclose(np.diff(ft), 1 / (1.05 * CFG.fps)) and np.isclose(ft[0], 3.5 / CFG.fps)
    # scale + pixel quantisation
    q = G.quantise_scale(a, 1.15, L)
    step = G.PIXEL_MM * L
    assert np.allclose(q / step, np.round(q / step), atol=1e-9)
    assert np.max(np.abs(q - 1.15 * a)) <= step / 2 + 1e-9


def test_forward_extension_inputs():
    avail = G.forward_extensions_available()
    modes = G.subglottal_modes(0.2, 1e6, 0.1)
    f = [m[0] for m in modes]
    assert np.allclose(f, [437.5, 1312.5, 2187.5])
    assert modes[0][2] > modes[1][2] > modes[2][2] and modes[0][1] < modes[1][1] < modes[2][1]
    if not avail["epithelium"]:
        pytest.skip("SimConfig has no epithelium fields")
    from vfcore.mesh import load_mesh

    prof = np.array(G.epithelium_profile(3.0, 1.0))
    m = load_mesh(CFG.mesh)
    assert prof.size == len(m.surface) - 1 and prof.min() >= 1.0 - 1e-12 and prof.max() > 2.5
    x_mid = 0.5 * (m.points[m.surface][1:, 0] + m.points[m.surface][:-1, 0])
    assert x_mid[np.argmax(prof)] > np.percentile(x_mid, 75)  # thickest on the medial surface
    CFG.replace(epithelium_E_kpa=10.0, epithelium_profile=tuple(prof))  # accepted by SimConfig


@pytest.mark.parametrize("label", G.EFFECTS + G.OUTSIDE + G.PAIRS)
def test_each_effect_changes_the_waveform(label):
    avail = G.forward_extensions_available()
    if label in avail and not avail[label]:
        pytest.skip(f"{label}: SimConfig lacks the forward-model fields")
    full = label not in G.EFFECTS
    c = G.make_case(
        "e",
        label,
        np.random.SeedSequence([3, G.LABELS.index(label)]),
        presence=False,
        material="full" if full else "three",
    )
    assert c.label == label and c.effect
    assert G.oscillates(c.clean, CFG.fps)
    # exposure at 2000 fps on a ~60-150 Hz GAW is a weak low-pass (documented in the README)
    assert c.effect_rms > (0.02 if label == "exposure" else 0.3), c.effect_rms
    ranges = {
        "sep_ratio": ("sep_ratio", G.SEP_RATIO_RANGES),
        "asymmetry": ("Q", G.ASYM_Q_RANGES),
        "frame_rate": ("rate_ratio", G.RATE_RANGES),
        "scale": ("scale", G.SCALE_RANGES),
    }
    if label in ranges:
        k, rr = ranges[label]
        assert any(lo <= c.effect[k] <= hi for lo, hi in rr)
    if label == "asymmetry":  # the right fold's layers are not scaled alike (richer than the fit)
        q = c.effect["Q_layers"]
        assert q["E_body"] == c.effect["Q"] and q["E_cover"] != q["E_body"] and q["E_lig"] != q["E_body"]
        for k in ("E_cover", "E_lig"):
            assert G.ASYM_LAYER_SPREAD[0] <= q[k] / c.effect["Q"] <= G.ASYM_LAYER_SPREAD[1]
    if label == "leak":
        assert G.LEAK_AREA_MM2[0] <= c.effect["chink_area_mm2"] <= G.LEAK_AREA_MM2[1]
        assert c.clean.min() >= c.effect["chink_area_mm2"] - 1e-9
    if "+" in label:  # both effects drawn, each with its own parameters
        assert set(c.effect) == set(label.split("+")) and all(c.effect.values())


def test_aligned_sse_finds_any_subframe_lag(base):
    g = np.asarray(base.gaw_hr, dtype=float)
    for start in (0.0, 123.0, 377.37, 1000.5):  # high-rate samples, fractional included
        t = start + 10 * np.arange(G.N_OBS)
        y = np.interp(t, np.arange(g.size), g)
        # The closed-form minimum rr + 2u rd + u^2 dd cancels terms of size sum(y^2): its round-off
        # is a few machine epsilons of that (1e-20 of it passed by luck and failed with a newer numpy).
        assert A._aligned_sse(y, g) < 64 * np.finfo(float).eps * np.sum(y**2), start
    y = np.interp(377.37 + 10 * np.arange(G.N_OBS), np.arange(g.size), g)
    assert A._aligned_sse(y + 0.5, g) > 0.5 * G.N_OBS * 0.25  # an offset is not a lag
    assert A._aligned_sse(y, g[:100]) == np.inf  # window shorter than the record


def test_presence_threshold_is_the_30_percent_bound():
    # a base fit that absorbs all but e, then an extension that removes e: RMS sqrt(s^2+e^2) -> s
    s = 0.7
    e = G.PRESENCE_SIGMA * s
    assert np.isclose(1 - s / np.hypot(s, e), 0.30)


@pytest.mark.slow  # 20 s on 2 cores; make test-all runs it
def test_unabsorbed_rms_control_and_scale(base):
    """The base model absorbs its own waveform exactly and most of a 15 % scale error (p_sub and
    the moduli trade amplitude for shape): the unabsorbed part is far below the effect itself."""
    truth = Params(**{**TABLE3.as_dict(), "E_body": 12.0, "E_cover": 600.0, "p_sub": 1000.0})
    r = simulate(truth, CFG)
    t = G.frame_times(G.N_OBS, 97.3, CFG.fps)
    clean = G.sample_hr(np.asarray(r.gaw_hr), G.hr_times(r), t)
    u0, fit0 = G.unabsorbed_rms(clean, truth, n_sobol=8, maxfev=10)
    assert u0 < 1e-6
    scaled = 0.85 * clean
    effect = np.sqrt(np.mean((scaled - clean) ** 2))
    u1, fit1 = G.unabsorbed_rms(scaled, truth, n_sobol=16, maxfev=60)
    assert 0.0 < u1 < 0.5 * effect, (u1, effect)
    assert fit1["p_sub"] < truth.p_sub  # the amplitude loss is absorbed by a lower pressure


def test_case_presence_flag():
    c = G.make_case("p", "leak", np.random.SeedSequence([3, 0]))
    assert np.isfinite(c.unabsorbed) and c.absorbing_fit
    assert c.present == (c.unabsorbed >= G.PRESENCE_SIGMA * c.sigma)
    assert c.present or c.notes
    ctl = G.make_case("c", "control", np.random.SeedSequence(11))
    assert not ctl.present and np.isnan(ctl.unabsorbed)


def test_asymmetry_is_entrained(base):
    """A right fold of another f0 is entrained 1:1: the combined GAW has the LEFT fold's f0 and
    repeats every left cycle (a generator that inverts the warp produces beating instead)."""
    from vfcore.measures import estimate_f0

    right = simulate(
        TABLE3.replace(E_body=1.3 * TABLE3.E_body, E_cover=1.3 * TABLE3.E_cover, E_lig=1.3 * TABLE3.E_lig), CFG
    )
    assert right.ok and abs(right.f0 / base.f0 - 1) > 0.08  # a clearly different fold
    t = G.frame_times(G.N_OBS, 77.3, CFG.fps)
    a = G.asymmetric_area(base, right, t, 0.1, t[G.N_OBS // 2])
    assert abs(estimate_f0(a, CFG.fps) / base.f0 - 1) < 0.01
    # one left period later the waveform repeats (to the folds' cycle-to-cycle variation)
    per = 1.0 / base.f0
    tt = t[(t > t[0] + per) & (t < t[-1] - 2 * per)]
    a1 = G.asymmetric_area(base, right, tt, 0.1, t[G.N_OBS // 2])
    a2 = G.asymmetric_area(base, right, tt + per, 0.1, t[G.N_OBS // 2])
    assert np.sqrt(np.mean((a1 - a2) ** 2)) < 0.05 * np.ptp(a1)


def test_audit_polishes_the_given_starts_and_can_only_lower_the_unabsorbed_rms(tmp_path):
    """The presence audit re-tests an existing suite: the generator's absorbing fit is among its
    starts, so a waveform the base model reproduces exactly at those materials comes out fully
    absorbed (not present) even when the recorded truth and the design are elsewhere; a control
    stays a control; audit.json is written, truth.json untouched."""
    import json

    absorbing = {"E_body": 12.0, "E_cover": 600.0, "p_sub": 1000.0}
    r = simulate(Params(**{**TABLE3.as_dict(), **absorbing}), CFG)
    clean = G.sample_hr(np.asarray(r.gaw_hr), G.hr_times(r), G.frame_times(G.N_OBS, 97.3, CFG.fps))
    far = {**TABLE3.as_dict(), "E_body": 9.5, "E_cover": 900.0, "p_sub": 1700.0}
    # the start alone finds it with a design of 2 points and 4 Nelder-Mead steps
    u, fit = G.unabsorbed_rms(clean, None, CFG, n_sobol=2, n_starts=1, maxfev=4, starts=[absorbing])
    assert u < 1e-6 and fit == pytest.approx(absorbing)
    hidden = {
        "seed": 0,
        "n_obs": G.N_OBS,
        "cases": {
            "00": {
                "label": "frame_rate",
                "truth": far,
                "sigma_mm2": 0.5,
                "unabsorbed_rms_mm2": 3.0,
                "present": True,
                "absorbing_fit": absorbing,
                "clean": clean.tolist(),
            },
            "01": {
                "label": "control",
                "truth": far,
                "sigma_mm2": 0.5,
                "unabsorbed_rms_mm2": float("nan"),
                "present": False,
                "absorbing_fit": {},
                "clean": clean.tolist(),
            },
        },
    }
    (tmp_path / "truth.json").write_text(json.dumps(hidden))
    before = (tmp_path / "truth.json").read_text()
    doc = G.audit_presence(tmp_path, config=CFG, search={"n_sobol": 2, "n_starts": 1, "maxfev": 4}, method="design")
    c = doc["cases"]["00"]
    assert c["unabsorbed_rms_mm2"] < 1e-6 and not c["present"] and c["generated_unabsorbed_rms_mm2"] == 3.0
    assert doc["cases"]["01"] == {"present": False}
    assert json.loads((tmp_path / "audit.json").read_text())["cases"]["00"]["present"] is False
    assert (tmp_path / "truth.json").read_text() == before


def test_certificate_marks_an_effect_the_base_fit_absorbs_and_never_one_it_does_not(tmp_path, capsys):
    """generate.py --certify polishes the base model from each report's base-posterior mean: a clean
    waveform the base model reproduces at that point is certified absorbed; one it cannot reproduce
    (the same waveform scaled by 1.5) is not; controls and cases without a report are skipped; the
    suite's files are untouched and absorption.json appears beside the reports."""
    import json

    absorbing = {"E_body": 12.0, "E_cover": 600.0, "p_sub": 1000.0}
    r = simulate(Params(**{**TABLE3.as_dict(), **absorbing}), CFG)
    clean = G.sample_hr(np.asarray(r.gaw_hr), G.hr_times(r), G.frame_times(G.N_OBS, 97.3, CFG.fps))
    far = {**TABLE3.as_dict(), "E_body": 9.5, "E_cover": 900.0, "p_sub": 1700.0}
    t = {"truth": far, "sigma_mm2": 0.5, "unabsorbed_rms_mm2": 3.0, "present": True, "absorbing_fit": {}}
    hidden = {
        "seed": 0,
        "n_obs": G.N_OBS,
        "cases": {
            "00": {**t, "label": "frame_rate", "clean": clean.tolist()},
            "01": {**t, "label": "scale", "clean": (1.5 * clean).tolist()},
            "02": {**t, "label": "control", "clean": clean.tolist()},
            "03": {**t, "label": "leak", "clean": clean.tolist()},
        },
    }
    suite, reps = tmp_path / "suite", tmp_path / "reports"
    suite.mkdir()
    reps.mkdir()
    (suite / "truth.json").write_text(json.dumps(hidden))
    base = {"base": {"params": {n: {"mean": v, "sd": 0.1} for n, v in absorbing.items()}}}
    for cid in ("00", "01", "02"):
        (reps / f"case_{cid}.json").write_text(json.dumps(base))
    before = (suite / "truth.json").read_text()
    doc = A.certify_absorption(suite, reps, config=CFG, maxfev=4)
    assert set(doc["cases"]) == {"00", "01"}
    assert doc["cases"]["00"]["absorbed"] and doc["cases"]["00"]["unabsorbed_rms_mm2"] < 1e-6
    assert not doc["cases"]["01"]["absorbed"] and doc["cases"]["01"]["unabsorbed_rms_mm2"] > 0.5
    assert json.loads((reps / "absorption.json").read_text())["cases"]["00"]["absorbed"] is True
    assert (suite / "truth.json").read_text() == before
    # the command line names what is missing
    with pytest.raises(SystemExit) as e:
        G.main(["--certify", str(suite)])
    assert e.value.code == 2 and "--reports" in capsys.readouterr().err
