"""The continuation stage: the base model and the refitted entries searched by window continuation
(:func:`.search.continuation_search`: fit the first cycles, double the window, polish, until the whole
recording) and fitted by an SMC started about the optimum (:func:`.search.continued_fit`). The base
model's fit joins the references as ``"base near continuation"``, so every gain is measured against
the best base fit found the same way; an entry's replaces its refit when its evidence is higher
(:ref:`diagnose-search-continuation-search`)."""

from __future__ import annotations

import math
import time

import numpy as np

from .extensions import get
from .fit import ExtendedPrior
from .refits import keep_if_higher
from .search import continuation_search, continuation_searches, continued_fit, continued_fits
from .seeds import stage_seed
from .state import DiagnosisState, Run
from .summary import best_particles

__all__ = ["search_base", "continue_all"]


def search_base(run: Run, st: DiagnosisState, starts, sd: int, label: str, copts: dict):
    """The base model searched by window continuation from ``starts`` (and the design ``copts``
    asks for), then fitted from the optimum; the fit's bound joins the references as
    ``"base near <label>"`` and ``st.before["mode_checks"][label]``. Returns ``(search, log Z, se,
    summary)``, or ``None`` when the search found no finite log-likelihood."""
    o = run.options
    t1 = time.perf_counter()
    fb = continuation_search(st.problem, None, starts=starts, seed=sd, map=run.map, chunk_size=o.chunk_size, **copts)
    st.n_simulations += fb.n_simulations
    if not math.isfinite(fb.loglik):
        return None
    zc, sc, pc = continued_fit(
        st.problem, fb, None, n_particles=st.refit_n, seed=sd, map=run.map, chunk_size=o.chunk_size, **run.smc
    )
    st.n_simulations += int(pc.n_simulations)
    sn = st.summary(pc)
    sn.update(
        wall_s=time.perf_counter() - t1, log_evidence_bound=zc, log_evidence_bound_se=sc, continuation=fb.to_dict()
    )
    st.before.setdefault("mode_checks", {})[label] = sn
    st.references[f"base near {label}"] = (zc, math.hypot(sc, st.tau), sn["residual_rms"])
    return fb, zc, sc, sn


def _searched_entries(run: Run, st: DiagnosisState) -> list[str]:
    """The refitted entries to search: all, or the ``continuation_entries`` of largest refit
    evidence (noted)."""
    k = run.options.continuation_entries
    entries = [n for n in st.chosen if n in st.refits]
    if k is None or len(entries) <= k:
        return entries
    z = {n: float(st.refits[n].log_evidence) for n in entries}
    top = set(sorted(entries, key=lambda n: -z[n] if math.isfinite(z[n]) else math.inf)[:k])
    st.notes.append(
        f"continuation: the {k} entries of largest refit evidence searched ("
        + ", ".join(n for n in entries if n in top)
        + "); not searched: "
        + ", ".join(n for n in entries if n not in top)
    )
    return [n for n in entries if n in top]


def continue_all(run: Run, st: DiagnosisState) -> None:
    """The base model, then every searched entry, by continuation (see the module docstring)."""
    copts = dict(run.options.continuation_options or {})
    sd = stage_seed(run.options.seed, "continuation", 0)
    entries = _searched_entries(run, st)
    run.track.at("continuation", "base", 0, len(entries))
    got = search_base(run, st, best_particles(st.base, 1), sd, "continuation", copts)
    fb = None
    if got is not None:
        fb, zc, sc, sn = got
        st.notes.append(
            f"continuation: the base model searched by window continuation (best log-likelihood "
            f"{fb.loglik:.1f}, {fb.n_simulations} simulations) and fitted from there: log Z = {zc:.1f} "
            f"+- {sc:.1f}, residual {sn['residual_rms']:.3f} mm^2"
        )
    if not entries:
        return
    # every entry's search at once (their starts share the cluster), then each entry's fit in turn
    run.track.at("continuation", "entries", 1, len(entries))
    o = run.options
    jobs = []
    for j, name in enumerate(entries):
        prior_e = ExtendedPrior(bounds={}, base=st.problem.prior, extension=name, integrate=bool(o.integrate))
        starts = [th for th in best_particles(st.refits[name], 1) if th.size == prior_e.ndim]
        if fb is not None:
            own = {p.name: (p.null if p.null is not None else 0.5 * (p.lo + p.hi)) for p in get(name).params}
            starts.append(np.concatenate([fb.theta, [own[n] for n in prior_e.names[prior_e.n_base :]]]))
        jobs.append((name, starts, stage_seed(o.seed, "continuation", j + 1)))
    found = continuation_searches(
        st.problem, jobs, map=run.map, chunk_size=o.chunk_size, integrate=o.integrate, **copts
    )
    # then every entry's fit from its optimum, the fits run together (each as alone)
    t1 = time.perf_counter()
    ok = [j for j, fe in enumerate(found) if math.isfinite(fe.loglik)]
    fits: dict = {}
    if ok:
        run.track.at("continuation", entries[ok[0]] if len(ok) == 1 else "entries", 1, len(entries))
        fits = dict(
            zip(
                ok,
                continued_fits(
                    st.problem,
                    [(found[j], entries[j], jobs[j][2]) for j in ok],
                    n_particles=st.refit_n,
                    map=run.map,
                    chunk_size=o.chunk_size,
                    integrate=o.integrate,
                    **run.smc,
                ),
            )
        )
    for j, (name, fe) in enumerate(zip(entries, found)):
        st.n_simulations += fe.n_simulations
        if j in fits:
            _keep_entry(run, st, name, fe, fits[j], t1)
        else:
            st.notes.append(f"continuation: the {name} search found no finite log-likelihood")


def _keep_entry(run: Run, st: DiagnosisState, name: str, fe, fit: tuple, t1: float) -> None:
    """Entry ``name``'s fit ``fit = (log Z, se, posterior)`` from the optimum its search found (from its
    refit's best particle and from the base's optimum with the entry at its null value); kept when higher."""
    zc, sc, pc = fit
    st.n_simulations += int(pc.n_simulations)
    z1 = float(st.refits[name].log_evidence)
    kept = keep_if_higher(run, st, name, pc, zc, t1, record=("continuation", fe.to_dict()), continued=True) is not None
    st.notes.append(
        f"continuation: {name} searched (best log-likelihood {fe.loglik:.1f}) and fitted from "
        f"there: log Z = {zc:.1f} +- {sc:.1f} against its first {z1:.1f}"
        + (" (kept)" if kept else " (not higher; the first is kept)")
    )
