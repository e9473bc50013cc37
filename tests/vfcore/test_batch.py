"""Batched forward model (vfcore.batch.simulate_many) against the scalar simulate."""

import numpy as np
import pytest

from vfcore import Params, SimConfig, simulate
from vfcore.batch import simulate_many

LO = np.array([9.0, 250.0, 0.5, 400.0, 950.0, 1.0, 7.4])  # paper priors, paper units
HI = np.array([15.0, 950.0, 3.0, 1800.0, 1200.0, 7.0, 8.4])


@pytest.fixture(scope="module")
def rows():
    # seed 2: rows 1 and 5 oscillate, row 4 diverges (ok=False), others are closed
    rng = np.random.default_rng(2)
    P = LO + (HI - LO) * rng.random((6, 7))
    return np.array([Params.from_array(r).as_array() for r in P])


@pytest.fixture(scope="module")
def scalar(rows):
    return [simulate(r, SimConfig()) for r in rows]


@pytest.fixture(scope="module")
def batched(rows):
    return simulate_many(rows, SimConfig(), block=6)


def test_small_blocks_take_the_scalar_kernel_with_the_same_bits(rows, batched, monkeypatch):
    """A block of fewer than MIN_LOCKSTEP rows goes to the scalar kernel: the lock-step kernel sees only the
    full blocks, and the small block's results equal those the lock-step kernel gave the same rows."""
    import vfcore.batch as vb

    sizes = []
    lockstep = vb._simulate_block

    def spy(ps, cfgs):
        sizes.append(len(ps))
        return lockstep(ps, cfgs)

    monkeypatch.setattr(vb, "_simulate_block", spy)
    out = simulate_many(rows, SimConfig(), block=5)  # a block of 5, then one of 1
    assert sizes == [5] and 1 < vb.MIN_LOCKSTEP <= 5
    one = simulate_many(rows[1:2], SimConfig())  # a single oscillating row
    assert sizes == [5]
    for b, s in zip(batched, out):
        assert b.ok == s.ok
        np.testing.assert_array_equal(b.gaw, s.gaw)
        np.testing.assert_array_equal(b.contact_force, s.contact_force)
    np.testing.assert_array_equal(one[0].gaw, batched[1].gaw)
    assert batched[1].gaw.max() > 1e-4


def test_batch_equals_scalar(scalar, batched):
    assert any(not s.ok for s in scalar) and sum(s.ok for s in scalar) >= 3
    assert any(s.ok and s.gaw.max() > 1e-4 for s in scalar)  # at least one oscillating sample
    for s, b in zip(scalar, batched):
        assert s.ok == b.ok and s.message == b.message
        if not s.ok:
            continue
        # bit for bit: both kernels evaluate every sum in source order (no fast-math, see
        # vfcore/solver/_kernels.py)
        for f in ("gaw", "gaw_hr", "width", "flow", "contact_pressure", "contact_force"):
            assert np.array_equal(getattr(s, f), getattr(b, f)), f
        # the per-cycle contact products include the kernels' projection impulses
        for f in (
            "contact_impulse",
            "contact_duration",
            "contact_pressure_in_contact",
            "max_contact_pressure_unconverged",
        ):
            assert np.array_equal(getattr(s.cycles, f), getattr(b.cycles, f)), f


@pytest.mark.parametrize("flow", ["paper", "continuous"])
def test_batch_equals_scalar_with_the_contact_layer(rows, flow):
    """The compliant contact layer (per-sample springs and dashpots) keeps the lock-step kernel equal
    to the scalar one bit for bit, contact forces included, with either flow load."""
    cfg = SimConfig(contact="layer", flow=flow, duration=0.2, discard=0.05)
    scalar = [simulate(r, cfg) for r in rows]
    batched = simulate_many(rows, cfg, block=6)
    assert any(s.ok and s.contact_force.max() > 0 for s in scalar)  # some sample touches the layer
    for s, b in zip(scalar, batched):
        assert s.ok == b.ok and s.message == b.message
        if s.ok:
            for f in ("gaw", "flow", "contact_pressure", "contact_force"):
                assert np.array_equal(getattr(s, f), getattr(b, f)), f
            for f in ("contact_impulse", "contact_pressure_in_contact", "max_contact_pressure_unconverged"):
                assert np.array_equal(getattr(s.cycles, f), getattr(b.cycles, f)), f


def test_batch_reruns_bit_identical(rows, batched):
    again = simulate_many(rows, SimConfig(), block=4)  # different blocking, same numbers
    for a, b in zip(batched, again):
        assert a.ok == b.ok
        if a.ok:
            assert np.array_equal(a.gaw, b.gaw) and np.array_equal(a.flow, b.flow)


def _close(s, b):
    """The batch-versus-scalar agreement of test_batch_equals_scalar (bit for bit)."""
    assert s.ok == b.ok and s.message == b.message
    if s.ok:
        for f in ("gaw", "flow", "contact_pressure", "p_in"):
            assert np.array_equal(getattr(s, f), getattr(b, f)), f


def test_per_row_extensions_share_one_block():
    """Rows with different model extensions (separation ratio, epithelium membrane, subglottal
    resonators with different mode counts) run in one lock-step block and each equals the scalar
    simulation with its own configuration."""
    from vfcore import TABLE3
    from vfcore.batch import block_key

    short = dict(duration=0.12, discard=0.06)
    cfgs = [
        SimConfig(**short),
        SimConfig(**short, sep_ratio=1.1),
        SimConfig(**short, epithelium_E_kpa=20.0),
        SimConfig(**short, subglottal_modes=((600.0, 0.1, 1e5),)),
        SimConfig(
            **short,
            subglottal_modes=((500.0, 0.1, 1e5), (1400.0, 0.05, 5e4)),
            sep_ratio=1.5,
            epithelium_E_kpa=40.0,
            epithelium_h_mm=0.03,
        ),
    ]
    assert len({block_key(c) for c in cfgs}) == 1
    rows = np.array([TABLE3.as_array()] * 3 + [TABLE3.replace(p_sub=800.0).as_array()] * 2)
    out = simulate_many(rows, block=8, configs=cfgs)
    scal = [simulate(r, c) for r, c in zip(rows, cfgs)]
    gaws = []
    for c, s, b in zip(cfgs, scal, out):
        _close(s, b)
        assert b.config == c
        if c.has_subglottal:
            assert np.ptp(b.p_in) > 1.0  # the resonators move the inlet pressure (Pa)
        else:
            assert b.p_in.size == 0
        gaws.append(b.gaw)
    # the extensions act: every row differs from the default row
    for g in gaws[1:3]:
        assert np.max(np.abs(g - gaws[0])) > 0.1


def test_configs_of_different_numerics_are_grouped():
    from vfcore import TABLE3

    short = dict(duration=0.08, discard=0.04)
    cfgs = [SimConfig(**short, mesh="coarse"), SimConfig(**short), SimConfig(**short, mesh="coarse", sep_ratio=1.2)]
    rows = np.array([TABLE3.as_array()] * 3)
    out = simulate_many(rows, configs=cfgs)
    for c, b, r in zip(cfgs, out, rows):
        assert b.config == c
        _close(simulate(r, c), b)
    with pytest.raises(ValueError, match="one SimConfig per row"):
        simulate_many(rows, configs=cfgs[:2])


def test_early_stop_saves_only_settled_draws_and_matches_the_scalar_kernel(rows):
    """SimConfig.early_stop: the lock-step kernel stops the same draws at the same step as the scalar one
    (bit for bit, with stopped samples leaving the block mid-run), a draw that oscillates is never
    stopped, and a stopped draw's GAW equals the full run's to within the stop tolerance."""
    cfg = SimConfig(mesh="coarse", duration=0.4, discard=0.1)
    full = simulate_many(rows, cfg, block=6)
    cut_scalar = [simulate(r, cfg.replace(early_stop=True)) for r in rows]
    cut = simulate_many(rows, cfg.replace(early_stop=True), block=6)
    stopped = [r.ok and r.settled_at > 0 for r in cut]
    assert any(stopped) and not all(r.settled_at > 0 for r in cut if r.ok)
    for f, s, b, st in zip(full, cut_scalar, cut, stopped):
        assert s.ok == b.ok == f.ok and s.settled_at == b.settled_at
        if not s.ok:
            continue
        for fld in ("gaw", "gaw_hr", "flow", "contact_force"):
            assert np.array_equal(getattr(s, fld), getattr(b, fld)), fld
        if np.ptp(f.gaw[-200:]) > 0.05:
            assert not st  # oscillating at the end: never stopped
        if st:
            # settled: the area varied by < 1.7e-4 mm^2 over the last two windows and keeps to that
            assert np.max(np.abs(b.gaw - f.gaw)) < 1e-3
            assert np.ptp(f.gaw[-200:]) < 1e-3  # the full run is indeed flat at the end
        else:
            assert np.array_equal(b.gaw, f.gaw)  # ran to the end: the same run
