"""The whole diagnosis: fit, locate, screen the catalogue, refit the promising extensions, name one.

``diagnose(problem)`` runs its stages in order (:ref:`diagnose-pipeline`), each a function of
the run's settings and the state the stages before it left (:mod:`.state`):

1. **Base fit** (:mod:`.baseline`, :func:`.material.material_first`) — the scaled parameters held at
   Table 3 freed first; tempered SMC of the base model, ``base_runs`` independent runs, the largest
   log-evidence kept; the fit's summary and its regularity.
2. **Locate** (:mod:`.locate`, :mod:`.summary`) — phase-folded residual and posterior-predictive
   p-values of the GAW measures; a base fit at the noise stops here (nothing could be named).
3. **Screen** (:mod:`.screen`) — every implemented extension scored at a few base particles; the
   score only chooses the refits.
4. **Refit** (:mod:`.refits`) — an SMC fit of each chosen entry; then, as the options ask, the
   rescue of refits that ended far below the base (:mod:`.rescue`), the shared mode
   (:mod:`.shared_mode`) and the continuation search (:mod:`.continuation`).
5. **Name** (:mod:`.naming`, :mod:`.checks`, :mod:`.rank`) — the naming rule, with the mode checks,
   the local check, best of all base fits and the nested check.
6. **Report** (:mod:`.report`) — the verdict, with the fit check (:mod:`.adequacy`).

Everything that costs simulations goes through ``map`` (a process pool's or a Dask client's), so
the same function runs on a laptop and on a cluster.
"""

from __future__ import annotations

from collections.abc import Callable

from ..inference.posterior import Posterior
from ..inference.problem import Problem
from .baseline import at_noise_floor, check_regularity, fit_base
from .continuation import continue_all
from .extensions import CATALOGUE, get
from .figure import plot_diagnosis
from .naming import name_winner
from .options import DiagnoseOptions
from .rank import rank_extensions
from .refits import refit_chosen
from .report import DiagnoseReport, finish
from .rescue import rescue_refits
from .screen import screen_catalogue
from .shared_mode import refit_from_leader
from .state import DiagnosisState, Run

__all__ = ["diagnose", "plot_diagnosis", "DiagnoseReport"]


def diagnose(
    problem: Problem,
    options: DiagnoseOptions | None = None,
    *,
    map=map,
    base: Posterior | None = None,
    progress: Callable[[dict], None] | None = None,
    **settings,
) -> DiagnoseReport:
    """Run the whole diagnosis on ``problem`` (see the module docstring).

    Parameters
    ----------
    problem : Problem
        The recording and the base model's prior.
    options : DiagnoseOptions, optional
        The settings (default: ``DiagnoseOptions()``, the command line's and the service's).
    map : callable
        ``map(fn, parts)`` through which every simulation batch runs.
    base : Posterior, optional
        A fit of the recording to start from: of ``problem``, or of it with fewer estimated
        parameters (then the pinned fit that freeing the material parameters is judged against).
    progress : callable, optional
        Given a dict at each stage and after each batch (:mod:`.progress`); it only watches.
    **settings
        Any :class:`DiagnoseOptions` field, replacing that of ``options``.

    Returns
    -------
    DiagnoseReport
    """
    opts = (options or DiagnoseOptions()).replace(**settings) if settings else (options or DiagnoseOptions())
    run = Run.start(opts, map, progress)
    st = DiagnosisState(
        problem=problem,
        base=base,
        refit_n=opts.refit_n,
        candidates=[n for n in (opts.candidates or CATALOGUE) if get(n).implemented],
    )
    fit_base(run, st)
    check_regularity(run, st)
    if at_noise_floor(run, st):
        return finish(run, st, rank_extensions(st.base, {}, **run.rule))
    screen_catalogue(run, st)
    refit_chosen(run, st)
    for repair in _repairs(opts):
        repair(run, st)
    return finish(run, st, name_winner(run, st))


def _repairs(opts: DiagnoseOptions) -> list:
    """The stages that may replace a refit by a better fit of the same entry, in order, as the
    options choose them."""
    return (
        [rescue_refits]
        + ([refit_from_leader] if opts.shared_mode else [])
        + ([continue_all] if opts.continuation else [])
    )
