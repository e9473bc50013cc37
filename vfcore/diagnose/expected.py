"""What a diagnosis is expected to cost, announced before it starts (``vfinfer diagnose`` prints it).

A diagnosis ends in one of two ways whose costs differ tenfold, and which one is not known before the
base fit: it stops at the noise after the base fit (``floor_stop``, :ref:`diagnose-naming`), or it
reaches the catalogue (refits, rescues, continuation searches, mode checks). The counts below are the
ranges measured on the held-out suite of seed 12 (:ref:`validation-diagnose`, all 19 finished cases,
every setting at its default, 2 workers):

* floor stops, 10 cases: 3,513–14,393 simulations. Two base runs of 40 particles cost 3,500–4,300; a
  base whose two runs disagree is fitted again with twice the particles (8,700–14,400);
* reaching the catalogue, 9 cases: 21,991–81,360 simulations.

Their time per simulation differs too. The base fits simulate a whole SMC generation in lock-step
blocks; the catalogue's stages also score waveform-level parameters by quadrature per simulation and run
single Nelder–Mead evaluations on the scalar kernel. Both are stated in units of the base model's own
time per simulation, measured before the run by :func:`vfcore.batch.probe_seconds_per_sim` (32 prior
draws, one lock-step block; 1.13–1.26 times a whole run on the suites' coarse mesh,
``benchmarks/bench_probe.py``): the suite's floor stops took a median 19.6 ms a simulation on 2 workers
(39 ms of a core) and its catalogue cases 36.8 ms, 0.8 of that on the current code (the one case run
on both, 28.6 and 22.8 ms), about 59 ms of a core, against the probe's 45–47 ms on the same machine.

The counts scale with the settings that set them (base particles and runs, refit particles, the number
of entries refitted and searched); with any of these away from its default the figures are scaled
linearly and marked as a guide: the ranges were not measured there. So is a diagnosis that holds some of
the five at Table 3 and frees them after a pinned fit (two base fits), or one given a base fit to reuse
(none).
"""

from __future__ import annotations

from dataclasses import dataclass

from .options import DiagnoseOptions

__all__ = [
    "ExpectedCost",
    "expected_cost",
    "expected_for",
    "base_fits",
    "FLOOR_SIMULATIONS",
    "CATALOGUE_SIMULATIONS",
    "FLOOR_TIME_FACTOR",
    "CATALOGUE_TIME_FACTOR",
]

#: Simulations of a diagnosis that stops after its base fit, at the defaults (seed 12, 10 cases).
FLOOR_SIMULATIONS = (3_513, 14_393)
#: Simulations of a diagnosis that reaches the catalogue, at the defaults (seed 12, 9 cases).
CATALOGUE_SIMULATIONS = (21_991, 81_360)
#: Core-seconds per simulation of each kind of diagnosis, in units of the base model's lock-step probe.
FLOOR_TIME_FACTOR = 0.85
CATALOGUE_TIME_FACTOR = 1.3

#: The settings the ranges were measured at, and those that change the simulation count.
_DEFAULT = DiagnoseOptions()
_CHANGING = (
    "n_particles",
    "base_runs",
    "refit_particles",
    "max_refits",
    "continuation",
    "continuation_entries",
    "escalate_factor",
    "shared_mode",
    "mode_checks",
)
_REFITS, _SEARCH, _CHECKS = 0.66, 0.28, 0.06


@dataclass(frozen=True)
class ExpectedCost:
    """Simulations and minutes of the two outcomes (minutes None when no time per simulation was
    given); ``guide`` names the settings that differ from the measured defaults (empty: the measured
    ranges themselves)."""

    floor: tuple[int, int]
    catalogue: tuple[int, int]
    floor_minutes: tuple[float, float] | None
    catalogue_minutes: tuple[float, float] | None
    seconds_per_simulation: float | None
    workers: int
    base_fits: int
    guide: tuple[str, ...]

    def lines(self, given: str = "--base fit") -> list[str]:
        """The announcement, one line per outcome; ``given`` names the reused base fit (``base_fits`` 0)."""

        def span(a, b, fmt):
            return f"{fmt(a)}-{fmt(b)}"

        ints, mins = (lambda v: f"{v:,}"), (lambda v: f"{v:.0f}" if v >= 10 else f"{v:.1f}")
        w = f"{self.workers} worker{'s' if self.workers > 1 else ''}"
        timed = self.seconds_per_simulation is not None

        def about(m):
            return f", about {span(*m, mins)} min" if timed else ""

        first = (
            f"if the {given} is already at the noise: no further base fit"
            if self.base_fits == 0
            else f"if the base fit reaches the noise (it stops there): {span(*self.floor, ints)} simulations"
            + about(self.floor_minutes)
        )
        head = (
            f"expected cost ({self.seconds_per_simulation * 1e3:.0f} ms a simulation on this machine, {w}): "
            if timed
            else "expected cost: "
        )
        out = [
            head + first,
            f"  if it goes on to the catalogue: {span(*self.catalogue, ints)} simulations"
            + about(self.catalogue_minutes),
        ]
        if self.guide:
            out.append("  (measured at the default settings; scaled for yours: " + ", ".join(self.guide) + ")")
        return out


def expected_cost(
    options: DiagnoseOptions,
    seconds_per_simulation: float | None,
    workers: int,
    *,
    base_fits: int = 1,
    n_entries: int | None = None,
) -> ExpectedCost:
    """The expected cost of a diagnosis with ``options`` on ``workers`` processes, given the base model's
    probed ``seconds_per_simulation`` (one core; None: simulations only). ``base_fits``: 1 as measured;
    0 when a given base fit is used as it is (its share left out), 2 when parameters held at Table 3 are freed after a
    pinned fit (:func:`.material.material_first`: the base share twice). ``n_entries``: the catalogue
    entries that will be refitted (None: all, as measured)."""
    timed = seconds_per_simulation is not None
    if (timed and seconds_per_simulation <= 0) or workers < 1 or base_fits not in (0, 1, 2):
        raise ValueError("seconds_per_simulation must be > 0, workers >= 1 and base_fits 0, 1 or 2")
    d = _DEFAULT
    base = options.n_particles * options.base_runs / (d.n_particles * d.base_runs) * max(base_fits, 1)
    from .extensions import implemented

    n_all = len(implemented())  # a diagnosis without candidates refits every implemented entry
    n = n_all if n_entries is None else int(n_entries)
    if options.max_refits is not None:
        # max_refits caps only the observation-level entries; the forward-level ones are always refitted
        from .options import OBSERVATION_ENTRIES

        n = min(n, n_all - OBSERVATION_ENTRIES + options.max_refits)
    refit = options.refit_n / d.refit_n * n / n_all
    searched = 0 if not options.continuation else min(n, options.continuation_entries or n)
    search = (1 + searched) / (1 + d.continuation_entries)
    # the catalogue's share split by stage as the suite's time was (refits and rescues 66 %, the
    # continuation stage 28 %, mode checks 6 %: the mean a case of its first group)
    rest = _REFITS * refit + _SEARCH * search + _CHECKS * options.mode_checks / d.mode_checks
    f_lo, f_hi = FLOOR_SIMULATIONS
    c_lo, c_hi = CATALOGUE_SIMULATIONS
    floor = (round(f_lo * base), round(f_hi * base))
    cat = (round(f_lo * base + (c_lo - f_lo) * rest), round(f_hi * base + (c_hi - f_hi) * rest))
    if base_fits == 0:
        cat = (cat[0] - floor[0], cat[1] - floor[1])
        floor = (0, 0)

    def minutes(sims, factor):
        return tuple(s * seconds_per_simulation * factor / workers / 60.0 for s in sims) if timed else None

    guide = tuple(
        f"{name} {getattr(options, name)!r}" for name in _CHANGING if getattr(options, name) != getattr(d, name)
    )
    if n_entries is not None and n_entries != n_all:
        guide = guide + (f"{n_entries} of {n_all} entries",)
    if base_fits == 2:
        guide = guide + ("a pinned base fit before the freed one",)
    if options.refit_start != d.refit_start:
        # not scaled: refits from the base cost 28 % fewer simulations on the nine catalogue cases of the
        # seed-12 suite (:ref:`validation-diagnose-pipeline-refits-started-from-the-base`), too few to give a range
        guide = guide + (f"refit_start {options.refit_start!r}, not scaled (fewer simulations than these)",)
    return ExpectedCost(
        floor,
        cat,
        minutes(floor, FLOOR_TIME_FACTOR),
        minutes(cat, CATALOGUE_TIME_FACTOR),
        float(seconds_per_simulation) if timed else None,
        int(workers),
        int(base_fits),
        guide,
    )


def base_fits(problem, options: DiagnoseOptions, base_post=None) -> int:
    """The base fits a diagnosis of ``problem`` with ``options`` runs before the catalogue: 0 when the
    given fit ``base_post`` is used as it is (it estimated the problem's own parameters and nothing is
    freed), 1 when it is the pinned fit the freed one is judged against, or when none is given and
    nothing is freed, 2 when none is given and the parameters held at Table 3 are freed after a pinned
    fit (:func:`.material.material_first`)."""
    from .material import pinned

    freed = options.free_material and bool(pinned(problem))
    if base_post is not None:
        return 1 if freed or tuple(base_post.names) != tuple(problem.prior.names) else 0
    return 2 if freed else 1


def expected_for(
    problem, options: DiagnoseOptions, seconds_per_simulation: float | None, workers: int, base_post=None
) -> ExpectedCost:
    """:func:`expected_cost` of a diagnosis of ``problem``: its base fits (:func:`base_fits`) and the
    implemented entries among ``options.candidates`` (all when None)."""
    from .extensions import get

    n = None if options.candidates is None else sum(get(c).implemented for c in options.candidates)
    return expected_cost(
        options, seconds_per_simulation, workers, base_fits=base_fits(problem, options, base_post), n_entries=n
    )
