"""Scoring of concealed-effect benchmark runs (benchmarks/scoring.py, bench_diagnose.py --score)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks import bench_diagnose  # noqa: E402
from benchmarks.scoring import format_summary, load_suite, summarise, wilson  # noqa: E402

BOX_NOTE = (
    "rescue: the leak refit ended at log Z -900.0, below the base's -500.0; refitted around the base's "
    "material mode: log Z >= -480.0 +- 0.5"
)
REF_NOTE = (
    "rescue: the epithelium refit ended at log Z -1275.9, below the base's -616.0; refitted from the base "
    "posterior (reference-started SMC): log Z = -700.1 +- 0.8 (not higher; the first refit is kept)"
)


def _report(winner, *, physics=None, gain=50.0, rms=0.5, notes=(), irregular=None, sims=1000, wall=10.0, rivals=()):
    d = {
        "verdict": "...",
        "winner": winner,
        "physics": physics,
        "rivals": [{"physics": p, "gap": 1.0, "se": 2.0} for p in rivals],
        "base": {"log_evidence": -500.0},
        "refits": {},
        "ranking": [],
        "reference": "base",
        "n_simulations": sims,
        "wall_s": wall,
        "notes": list(notes),
    }
    if irregular is not None:
        d["base"]["regularity"] = {"irregular": irregular}
    if winner:
        d["refits"][winner] = {"rms_improvement": rms}
        d["ranking"] = [{"name": winner, "delta": gain}]
    return d


def _truth(label, *, present=True, unabs=3.0, sigma=1.0):
    return {"label": label, "present": present, "unabsorbed_rms_mm2": unabs, "sigma_mm2": sigma, "effect_loglik": 100.0}


def _suite(tmp_path: Path, name: str, cases: dict) -> tuple[Path, Path]:
    cdir, odir = tmp_path / name, tmp_path / f"{name}_out"
    cdir.mkdir()
    odir.mkdir()
    (cdir / "truth.json").write_text(json.dumps({"cases": {cid: t for cid, (t, _) in cases.items()}}))
    for cid, (_, rep) in cases.items():
        if rep is not None:
            (odir / f"case_{cid}.json").write_text(json.dumps(rep))
    return cdir, odir


@pytest.fixture
def suite(tmp_path):
    return _suite(
        tmp_path,
        "s1",
        {
            "00": (
                _truth("leak", unabs=3.0),
                {
                    **_report("leak", irregular=False, notes=[BOX_NOTE]),
                    "cost": {
                        "by_stage": {
                            "base fit": {"wall_s": 100.0},
                            "refit": {"wall_s": 200.0},
                            "continuation": {"wall_s": 600.0},
                        }
                    },
                },
            ),
            # lr_stiffness is an asymmetry model: a zipper named as it is a miss
            "01": (_truth("zipper", unabs=1.5), _report("lr_stiffness", physics="asymmetry", irregular=True)),
            "02": (_truth("control"), _report(None, notes=[REF_NOTE])),
            "03": (_truth("control"), _report("scale", rms=0.2, gain=-1.0)),
            "04": (_truth("scale", present=False, unabs=0.5), _report(None)),
            # the physics field is absent: the scorer maps lr_stiffness to asymmetry itself
            "05": (
                _truth("asymmetry", unabs=1.0),
                {
                    **_report("lr_stiffness", irregular=False),
                    "cost": {"by_stage": {"base fit": {"wall_s": 20.0}, "refit": {"wall_s": 100.0}}},
                },
            ),
            # named wrong, but the truth is listed as a rival the evidence does not separate
            "08": (_truth("scale", unabs=2.5), _report("zipper", rivals=["scale", "sep_ratio"])),
            "06": (_truth("subglottal", unabs=5.0), {"error": "GAW has NaN at frame 3", "winner": None}),
            "07": (_truth("epithelium", unabs=4.0), None),  # not diagnosed yet: skipped
        },
    )


def test_wilson_matches_the_closed_form():
    for k, n in [(10, 16), (0, 4), (38, 62), (16, 16)]:
        z, p = 1.959963984540054, k / n
        c = (p + z * z / (2 * n)) / (1 + z * z / n)
        h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
        lo, hi = wilson(k, n)
        assert lo == pytest.approx(c - h, abs=1e-9) and hi == pytest.approx(c + h, abs=1e-9)
    assert all(math.isnan(x) for x in wilson(0, 0))


def test_records_join_reports_and_truth(suite):
    recs = {r.case: r for r in load_suite(*suite)}
    assert sorted(recs) == ["00", "01", "02", "03", "04", "05", "06", "08"]
    assert not recs["08"].ok and recs["08"].rivals == ["scale", "sep_ratio"]
    assert recs["00"].ok and recs["00"].irregular is False and recs["00"].rescues == [("leak", "box", True)]
    assert not recs["01"].ok and recs["01"].physics == "asymmetry"
    assert recs["02"].ok and recs["02"].rescues == [("epithelium", "reference", False)]
    assert not recs["03"].ok  # a false alarm
    assert recs["05"].ok and recs["05"].physics == "asymmetry"
    assert recs["06"].winner == "rejected" and not recs["06"].ok
    assert recs["01"].strength_sd == pytest.approx(1.5) and math.isnan(recs["02"].strength_sd)


def test_summary_counts(suite):
    s = summarise(load_suite(*suite))
    # present effect cases: 00 (right), 01 (wrong), 05 (right), 06 (rejected), 08 (wrong, truth a rival)
    assert (s["present"]["named"], s["present"]["of"]) == (2, 5)
    assert (s["all_effect_cases"]["named"], s["all_effect_cases"]["of"]) == (2, 6)
    assert (s["named_or_rival"]["named"], s["named_or_rival"]["of"]) == (3, 5)
    assert (s["false_alarms"]["count"], s["false_alarms"]["of"]) == (1, 2)
    assert (s["by_effect"]["zipper"]["named"], s["by_effect"]["zipper"]["of"]) == (0, 1)
    assert s["by_strength"]["weak (< 2 sd)"]["named"] == 1 and s["by_strength"]["weak (< 2 sd)"]["of"] == 2
    assert s["by_strength"]["strong (>= 2 sd)"]["of"] == 3
    assert s["by_base_regularity"]["irregular"]["of"] == 1 and s["by_base_regularity"]["unknown"]["of"] == 2
    assert s["misses"] == {"scale -> zipper": 1, "subglottal -> none": 1, "zipper -> asymmetry": 1}
    assert s["rescues"] == {"box": {"fired": 1, "kept": 1}, "reference": {"fired": 1, "kept": 0}}
    # named: 00, 01, 03, 05, 08; 03's gain is negative and its RMS gain 20 %
    assert s["named_rms_ge_30pct"] == [4, 5] and s["named_positive_gain"] == [4, 5]
    assert "2/5 (40 %" in format_summary(s)
    # time by stage: only the reports that carry their cost (00 and 05), a stage absent from one counts 0 s
    assert s["wall_by_stage"] == {"cases": 2, "mean_s": {"continuation": 300.0, "refit": 150.0, "base fit": 60.0}}
    assert (
        "wall per case by stage (2 reports with their cost): continuation 300 s, refit 150 s, base fit 60 s"
        in format_summary(s)
    )


def test_suites_pool(tmp_path, suite):
    other = _suite(tmp_path, "s2", {"00": (_truth("leak"), _report("leak")), "01": (_truth("control"), _report(None))})
    s = summarise(load_suite(*suite) + load_suite(*other))
    assert (s["present"]["named"], s["present"]["of"]) == (3, 6)
    assert (s["false_alarms"]["count"], s["false_alarms"]["of"]) == (1, 3)
    assert s["suites"] == ["s1", "s2"]


def test_cli_score_pools_and_rejects_unequal_lists(tmp_path, suite, capsys):
    other = _suite(tmp_path, "s2", {"00": (_truth("leak"), _report("leak"))})
    bench_diagnose.main(["--score", "--cases", f"{suite[0]},{other[0]}", "--out", f"{suite[1]},{other[1]}"])
    out = capsys.readouterr().out
    assert "s2/00" in out and "effect present, named right: 3/6" in out
    with pytest.raises(SystemExit, match="2 --cases directories but 1 --out"):
        bench_diagnose.main(["--score", "--cases", f"{suite[0]},{other[0]}", "--out", str(suite[1])])


def test_missing_truth_is_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="no truth.json"):
        load_suite(tmp_path, tmp_path)


def test_reference_floor_and_presence_audit(tmp_path):
    """The floor is 1 - sigma / RMS of the report's *reference* fit (base, base near an entry, or a
    null-consistent refit); audit.json moves cases out of the present set for the audited rate
    only, and never into the generator's own present-effect rate."""
    from benchmarks.scoring import reference_rms

    def rep(winner, reference, base_rms=2.0, near=None, null_refit=None):
        d = _report(winner)
        d["reference"] = reference
        d["base"]["residual_rms"] = base_rms
        if near:
            d["base"]["mode_checks"] = {near[0]: {"residual_rms": near[1]}}
        if null_refit:
            d["refits"][null_refit[0]] = {"residual_rms": null_refit[1], "rms_improvement": 0.0}
        return d

    r_base = rep(None, "base", base_rms=2.0)
    r_near = rep(None, "base near scale", base_rms=2.0, near=("scale", 1.25))
    r_null = rep("leak", "exposure", base_rms=2.0, null_refit=("exposure", 1.6))
    assert reference_rms(r_base) == 2.0 and reference_rms(r_near) == 1.25 and reference_rms(r_null) == 1.6
    cdir, odir = _suite(
        tmp_path,
        "s",
        {
            "00": (_truth("scale", unabs=3.0, sigma=1.0), r_base),  # missed, floor 50 %
            "01": (_truth("frame_rate", unabs=3.0, sigma=1.0), r_near),  # missed, floor 20 %
            "02": (_truth("leak", unabs=2.0, sigma=0.8), r_null),  # named right, floor 50 %
            "03": (_truth("control"), rep(None, "base")),
        },
    )
    (cdir / "audit.json").write_text(
        json.dumps(
            {
                "cases": {
                    "00": {"present": True},
                    "01": {"present": False},
                    "02": {"present": True},
                    "03": {"present": False},
                }
            }
        )
    )
    recs = {r.case: r for r in load_suite(cdir, odir)}
    assert recs["00"].floor_gain == pytest.approx(0.5) and recs["01"].floor_gain == pytest.approx(0.2)
    assert recs["02"].floor_gain == pytest.approx(0.5)
    assert recs["01"].audit_present is False and recs["03"].audit_present is None
    s = summarise(list(recs.values()))
    assert (s["present"]["named"], s["present"]["of"]) == (1, 3)  # the generator's rule
    assert (s["present_under_audit"]["named"], s["present_under_audit"]["of"]) == (1, 2)
    assert s["audited_cases"] == 3 and s["misses_floor_below_30pct"] == [1, 2]
    out = format_summary(s)
    assert "under the presence audit (3 effect cases audited" in out and "1/2 (50 %" in out


TABLE = """case truth       named       ok      dlogZ RMS impr   sims  wall s  effect ll unabs/sd  reference
00   control     None        Y         nan     nan%   7623     100        0.0      nan  base
04   asymmetry   lr_stiffnessY       313.6      37%  31441     421    10031.7     1.86  base; rivals: zipper
10   frame_rate  asymmetry   N      1175.4      50%  42052     589   431015.9     9.66  base; rivals: zipper, asymmetry
14   scale       None        N         nan     nan%   7903      98     4438.7     1.40  base near scale
"""


def test_kept_table_is_scored_against_the_regenerated_suite(tmp_path):
    """A suite whose reports were not kept is scored from its printed table: the glued named/ok
    columns, rivals and reference parse, the audit applies to the rows that regenerate (to 1e-4 of
    their effect log-likelihood), a row that does not is scored as tabled without it, and a table
    of another suite is refused by name."""
    from benchmarks.scoring import load_table

    cases = {
        "00": {"label": "control", "effect_loglik": 0.0, "sigma_mm2": 0.5},
        "04": {
            "label": "asymmetry",
            "effect_loglik": 10031.66,
            "unabsorbed_rms_mm2": 1.86,
            "sigma_mm2": 1.0,
            "present": True,
        },
        "10": {
            "label": "frame_rate",
            "effect_loglik": 431015.94,
            "unabsorbed_rms_mm2": 9.66,
            "sigma_mm2": 1.0,
            "present": True,
        },
        "14": {"label": "scale", "effect_loglik": 4438.7, "unabsorbed_rms_mm2": 1.4, "sigma_mm2": 1.0, "present": True},
    }
    cdir = tmp_path / "s"
    cdir.mkdir()
    (cdir / "truth.json").write_text(json.dumps({"cases": cases}))
    (cdir / "audit.json").write_text(
        json.dumps({"cases": {"04": {"present": True}, "10": {"present": True}, "14": {"present": False}}})
    )
    table = tmp_path / "score_table.txt"
    table.write_text(TABLE)
    recs = {r.case: r for r in load_table(cdir, table)}
    assert recs["04"].winner == "lr_stiffness" and recs["04"].physics == "asymmetry" and recs["04"].ok
    assert recs["04"].rivals == ["zipper"] and recs["04"].gain == 313.6 and recs["04"].rms_improvement == 0.37
    assert recs["10"].physics == "asymmetry" and not recs["10"].ok and recs["10"].rivals == ["zipper", "asymmetry"]
    assert recs["14"].winner is None and recs["14"].reference == "base near scale"
    assert recs["00"].ok and recs["00"].label == "control" and math.isnan(recs["00"].gain)
    s = summarise(list(recs.values()))
    assert (s["present"]["named"], s["present"]["of"]) == (1, 3)
    assert (s["present_under_audit"]["named"], s["present_under_audit"]["of"]) == (1, 2)  # 14 absorbed
    assert s["not_regenerated"] == [] and s["misses_floor_below_30pct"] == [0, 0]  # no floor in a table
    # a last-digit change of the forward model is the same recording (1e-4 relative)...
    cases["10"]["effect_loglik"] = 431016.2
    cases["14"]["effect_loglik"] = 4438.7 + 0.4
    (cdir / "truth.json").write_text(json.dumps({"cases": cases}))
    assert all(r.regenerated for r in load_table(cdir, table))
    # ...a changed mechanism is not: the row is scored as tabled, without the audit
    cases["14"]["effect_loglik"] = 4438.7 + 2.0
    cases["14"]["unabsorbed_rms_mm2"] = 0.5  # the regenerated truth's strength is not used
    (cdir / "truth.json").write_text(json.dumps({"cases": cases}))
    recs = {r.case: r for r in load_table(cdir, table)}
    assert not recs["14"].regenerated and recs["14"].audit_present is None and recs["14"].present
    assert recs["14"].strength_sd == 1.40 and recs["10"].regenerated and recs["10"].audit_present is True
    s = summarise(list(recs.values()))
    assert (s["present_under_audit"]["named"], s["present_under_audit"]["of"]) == (1, 3)  # 14 as tabled
    assert s["not_regenerated"] == ["s/14"] and "not regenerated" in format_summary(s)
    # another suite (a label differs) or no effect row reproduced: refused by name
    cases["04"]["label"] = "leak"
    (cdir / "truth.json").write_text(json.dumps({"cases": cases}))
    with pytest.raises(ValueError, match="case 04 .*not the suite"):
        load_table(cdir, table)
    cases["04"]["label"] = "asymmetry"
    for c in ("04", "10"):
        cases[c]["effect_loglik"] += 5000.0
    (cdir / "truth.json").write_text(json.dumps({"cases": cases}))
    with pytest.raises(ValueError, match="did not regenerate"):
        load_table(cdir, table)


@pytest.mark.parametrize("search", ["window", "periods"])
def test_problem_carries_lag_search(tmp_path, search):
    """--lag-search reaches the fitting problem (a controlled comparison of the two lag rules depends on it)."""
    meta = {
        "model": {"mesh": "coarse", "dt": 1e-4, "duration": 0.55, "discard": 0.25},
        "fixed": {"E_lig": 1.808, "rho": 1051.0, "eta": 3.079, "x0": 8.4},
    }
    import numpy as np

    t = np.arange(400) / 2000.0
    np.savetxt(
        tmp_path / "c.csv",
        5.0 * np.clip(np.sin(2 * np.pi * 120 * t), 0, None)[:, None],
        delimiter=",",
        header="area",
        comments="",
    )
    from benchmarks.suite import case_problem

    pb = case_problem(meta, {"file": "c.csv", "fps": 2000.0}, tmp_path, None, 1.0, None, "fixed", search)
    assert pb.lag_search == search
    assert type(pb).from_dict(pb.to_dict()).lag_search == search


def test_one_case_reads_the_asked_case_and_names_a_missing_one(tmp_path):
    import json

    from benchmarks.suite import one_case

    meta = {"model": {}, "cases": [{"id": "00", "file": "a.csv"}, {"id": "07", "file": "b.csv"}]}
    (tmp_path / "cases.json").write_text(json.dumps(meta))
    got, case = one_case(tmp_path, "07")
    assert case["file"] == "b.csv" and got == meta
    with pytest.raises(ValueError, match="no case '7' in"):
        one_case(tmp_path, "7")


def test_pairs_outside_effects_and_no_fit_verdicts_are_scored_apart(tmp_path):
    no_fit = {"fit_check": {"fits": False}}
    cdir, odir = _suite(
        tmp_path,
        "full",
        {
            "00": (_truth("sep_ratio+leak"), _report("leak", physics="leak")),  # either effect is right
            "01": (_truth("epithelium+scale"), _report("zipper", physics="zipper")),  # a wrong name
            "02": (_truth("tremor"), _report(None) | no_fit),  # silent, by "no fit"
            "03": (_truth("gamma"), _report("scale", physics="scale")),  # a name where none is right
            "04": (_truth("leak"), _report(None) | no_fit),
            "05": (_truth("control"), _report(None) | {"material": {"found": True}}),
        },
    )
    recs = {r.case: r for r in load_suite(cdir, odir)}
    assert recs["00"].ok and not recs["01"].ok and recs["02"].ok and not recs["03"].ok
    assert recs["02"].outside and recs["02"].no_fit and recs["05"].material and recs["05"].ok
    s = summarise(list(recs.values()))
    assert (s["present"]["named"], s["present"]["of"]) == (1, 3)
    assert (s["wrong_names"]["named"], s["wrong_names"]["of"]) == (1, 3)
    assert (s["no_fit"]["present"]["named"], s["no_fit"]["outside"]["named"]) == (1, 1)
    assert (s["outside_silent"]["named"], s["outside_silent"]["of"]) == (1, 2)
    assert s["material_verdicts"] == 1 and s["false_alarms"]["count"] == 0
    text = format_summary(s)
    assert "wrong name: 1/3" in text and "outside the catalogue left unnamed: 1/2" in text


def test_absorption_certificate_only_removes_cases_from_the_secondary_rate(tmp_path):
    """absorption.json (generate.py --certify) takes an effect the diagnosis's base fit absorbed out of
    the secondary rate "present under the audit and not absorbed"; a case it does not show absorbed
    stays, a control is never certified, and the protocol's own rates do not move."""
    cdir, odir = _suite(
        tmp_path,
        "s",
        {
            "00": (_truth("scale"), _report(None)),  # missed, absorbed from the base
            "01": (_truth("leak"), _report("leak")),  # named right, not shown absorbed
            "02": (_truth("zipper"), _report(None)),  # missed, not certified
            "03": (_truth("frame_rate", present=False), _report(None)),  # absent already: never added back
            "04": (_truth("control"), _report(None)),
        },
    )
    (odir / "absorption.json").write_text(
        json.dumps(
            {
                "cases": {
                    "00": {"absorbed": True},
                    "01": {"absorbed": False},
                    "03": {"absorbed": False},
                    "04": {"absorbed": True},
                }
            }
        )
    )
    recs = {r.case: r for r in load_suite(cdir, odir)}
    assert recs["00"].base_absorbed is True and recs["01"].base_absorbed is False
    assert recs["02"].base_absorbed is None and recs["04"].base_absorbed is None
    s = summarise(list(recs.values()))
    assert (s["present"]["named"], s["present"]["of"]) == (1, 3)
    assert (s["present_not_absorbed"]["named"], s["present_not_absorbed"]["of"]) == (1, 2)
    assert s["absorbed_from_base"] == ["00"] and s["certified_cases"] == 3
    assert "absorbed from the diagnosis' base fit (3 effect cases certified" in format_summary(s)
    # without the file nothing is certified and the line is absent
    (odir / "absorption.json").unlink()
    s = summarise(load_suite(cdir, odir))
    assert s["certified_cases"] == 0 and "absorbed from the diagnosis' base fit" not in format_summary(s)
