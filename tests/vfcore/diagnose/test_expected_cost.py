"""The cost a diagnosis announces before it starts (vfcore.diagnose.expected): at the defaults it is the
held-out suite's measured ranges, and it moves with the settings that set the simulation count."""

from __future__ import annotations

import pytest

from vfcore.diagnose.expected import (
    CATALOGUE_SIMULATIONS,
    CATALOGUE_TIME_FACTOR,
    FLOOR_SIMULATIONS,
    FLOOR_TIME_FACTOR,
    expected_cost,
)
from vfcore.diagnose.options import DiagnoseOptions


def test_the_defaults_announce_the_measured_ranges_and_minutes_follow_the_probe():
    c = expected_cost(DiagnoseOptions(), 0.04, 2)
    assert c.floor == FLOOR_SIMULATIONS and c.catalogue == CATALOGUE_SIMULATIONS and c.guide == ()
    assert c.floor_minutes == pytest.approx([s * 0.04 * FLOOR_TIME_FACTOR / 2 / 60 for s in FLOOR_SIMULATIONS])
    assert c.catalogue_minutes == pytest.approx(
        [s * 0.04 * CATALOGUE_TIME_FACTOR / 2 / 60 for s in CATALOGUE_SIMULATIONS]
    )
    # one worker takes twice as long for the same simulations
    one = expected_cost(DiagnoseOptions(), 0.04, 1)
    assert one.catalogue == c.catalogue and one.catalogue_minutes == pytest.approx([2 * m for m in c.catalogue_minutes])
    text = "\n".join(c.lines())
    assert f"{FLOOR_SIMULATIONS[0]:,}-{FLOOR_SIMULATIONS[1]:,} simulations" in text
    assert f"{CATALOGUE_SIMULATIONS[0]:,}-{CATALOGUE_SIMULATIONS[1]:,} simulations" in text
    assert "scaled" not in text


def test_the_count_moves_with_the_settings_that_set_it_and_says_it_is_scaled():
    d = expected_cost(DiagnoseOptions(), 0.04, 2)
    more = expected_cost(DiagnoseOptions(n_particles=80), 0.04, 2)
    assert more.floor == (2 * d.floor[0], 2 * d.floor[1])
    # the catalogue stages are unchanged: only the base share grows
    assert more.catalogue[1] - more.floor[1] == d.catalogue[1] - d.floor[1]
    assert "n_particles 80" in "\n".join(more.lines())
    for fewer in (
        DiagnoseOptions(refit_particles=12),
        DiagnoseOptions(continuation=False),
        DiagnoseOptions(continuation_entries=2),
        DiagnoseOptions(max_refits=0),
    ):
        c = expected_cost(fewer, 0.04, 2)
        assert c.floor == d.floor and c.catalogue[0] < d.catalogue[0] and c.catalogue[1] < d.catalogue[1]
        assert c.guide, fewer
    few = expected_cost(DiagnoseOptions(), 0.04, 2, n_entries=2)
    assert few.catalogue[1] < d.catalogue[1] and "2 of" in "\n".join(few.lines())
    # refits from the base are named, not scaled: their ranges were not measured
    b = expected_cost(DiagnoseOptions(refit_start="base"), 0.04, 2)
    assert (b.floor, b.catalogue) == (d.floor, d.catalogue)
    assert "refit_start 'base', not scaled" in "\n".join(b.lines())


def test_a_reused_base_fit_leaves_out_the_base_share_and_a_pinned_one_doubles_it():
    d = expected_cost(DiagnoseOptions(), 0.04, 2)
    b = expected_cost(DiagnoseOptions(), 0.04, 2, base_fits=0)
    assert b.floor == (0, 0)
    assert b.catalogue == (d.catalogue[0] - d.floor[0], d.catalogue[1] - d.floor[1])
    assert "--base" in b.lines()[0]
    two = expected_cost(DiagnoseOptions(), 0.04, 2, base_fits=2)
    assert two.floor == (2 * d.floor[0], 2 * d.floor[1])
    assert two.catalogue[1] - two.floor[1] == d.catalogue[1] - d.floor[1] and "pinned" in "\n".join(two.lines())


def test_nonsense_is_refused():
    with pytest.raises(ValueError):
        expected_cost(DiagnoseOptions(), 0.0, 2)
    with pytest.raises(ValueError):
        expected_cost(DiagnoseOptions(), 0.04, 0)
    with pytest.raises(ValueError):
        expected_cost(DiagnoseOptions(), 0.04, 2, base_fits=3)


def test_the_base_fits_follow_the_given_fit_and_what_is_freed(monkeypatch):
    """No fit given: one base fit, two when parameters held at Table 3 are freed after a pinned one. A
    given fit of the problem's own parameters is the base as it is (none), unless parameters are freed
    (it is then the pinned fit: one more) or it estimated other parameters (one)."""
    from types import SimpleNamespace

    import vfcore.diagnose.material as M
    from vfcore.diagnose.expected import base_fits, expected_for

    problem = SimpleNamespace(prior=SimpleNamespace(names=("E_body", "E_cover")))
    same, other = SimpleNamespace(names=("E_body", "E_cover")), SimpleNamespace(names=("E_cover",))
    for held, want in (([], {None: 1, "same": 0, "other": 1}), (["p_sub"], {None: 2, "same": 1, "other": 1})):
        monkeypatch.setattr(M, "pinned", lambda p, held=held: held)
        for free in (True, False):
            got = {
                k: base_fits(problem, DiagnoseOptions(free_material=free), post)
                for k, post in ((None, None), ("same", same), ("other", other))
            }
            assert got == (want if free else {None: 1, "same": 0, "other": 1}), (held, free)
    monkeypatch.setattr(M, "pinned", lambda p: ["p_sub"])
    c = expected_for(problem, DiagnoseOptions(candidates=["leak", "asymmetry"]), None, 2)
    assert c.base_fits == 2 and c.floor == (2 * FLOOR_SIMULATIONS[0], 2 * FLOOR_SIMULATIONS[1])
    assert c.floor_minutes is None and c.catalogue_minutes is None and "2 of" in "\n".join(c.guide)
    assert "about" not in "\n".join(c.lines()) and "ms a simulation" not in c.lines()[0]
