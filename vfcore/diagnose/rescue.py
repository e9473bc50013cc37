"""The rescue: a refit that ended far below the base missed the base-like region of its own model
(every entry is, or comes arbitrarily close to, the base model at its null value), so it is refitted
near the base's material mode and the new evidence kept when larger (:ref:`diagnose-pipeline`,
"Rescue"). How it is refitted is a strategy chosen once (:data:`RESCUES`)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from ..inference.posterior import Posterior
from .extensions import get
from .mode_fits import base_near, reference_refit, reference_refits
from .refits import keep_if_higher, starts_from_base
from .seeds import stage_seed
from .state import DiagnosisState, Run

__all__ = ["Rescue", "RESCUES", "rescue_refits"]


@dataclass(frozen=True)
class Rescue:
    """How a failed refit is refitted: ``refit(run, state, name, seed) -> (log Z, se, posterior)``, the
    report's words for it (``how``, and ``relation`` of the new value to the evidence: an estimate or a
    bound), the ``info`` tag of the new fit, and ``record(posterior)``: what the report keeps of it.
    ``refit_many(run, state, [(name, seed), ...])``, where given, refits several entries together, each
    as ``refit`` would alone (one batch a round through the map)."""

    method: str
    how: str
    relation: str
    tag: str
    refit: Callable
    record: Callable[[Posterior], dict]
    refit_many: Callable | None = None


def _from_reference(run: Run, st: DiagnosisState, name: str, seed: int):
    """An SMC started from the base posterior (:func:`.mode_fits.reference_refit`): its result
    estimates the extended model's evidence, with no box and no prior-volume penalty."""
    o = run.options
    return reference_refit(
        st.problem,
        st.base,
        name,
        n_particles=st.refit_n,
        seed=seed,
        map=run.map,
        chunk_size=o.chunk_size,
        inflate=o.rescue_inflate,
        integrate=o.integrate,
        **run.smc,
    )


def _from_reference_together(run: Run, st: DiagnosisState, jobs: list[tuple[str, int]]):
    """:func:`_from_reference` of every ``(entry, seed)``, the fits run together
    (:func:`.mode_fits.reference_refits`; each as alone)."""
    o = run.options
    return reference_refits(
        st.problem,
        st.base,
        [(name, st.refit_n, seed) for name, seed in jobs],
        map=run.map,
        chunk_size=o.chunk_size,
        inflate=o.rescue_inflate,
        integrate=o.integrate,
        **run.smc,
    )


def _on_box(run: Run, st: DiagnosisState, name: str, seed: int):
    """An SMC on a box of ``+- rescue_half_width`` of each material parameter's prior width around the
    base posterior (:func:`.mode_fits.base_near`): a lower bound on the extended evidence."""
    o = run.options
    return base_near(
        st.problem,
        st.base,
        n_particles=st.refit_n,
        seed=seed,
        map=run.map,
        chunk_size=o.chunk_size,
        half_width=o.rescue_half_width,
        extension=name,
        integrate=o.integrate,
        **run.smc,
    )


def _box_record(near: Posterior) -> dict:
    return {
        "box": near.info["box"],
        "boxes": near.info["boxes"],
        "log_box_probability": near.info["log_box_probability"],
    }


#: The rescue strategy of each ``DiagnoseOptions.rescue_method``.
RESCUES = {
    "reference": Rescue(
        "reference",
        "from the base posterior (reference-started SMC)",
        "=",
        "reference_refit_of",
        _from_reference,
        lambda near: {},
        _from_reference_together,
    ),
    "box": Rescue("box", "around the base's material mode", ">=", "box_refit_of", _on_box, _box_record),
}


def rescue_refits(run: Run, st: DiagnosisState) -> None:
    """Refit every rescuable entry whose refit ended more than ``max(min_gain, k_se se)`` below the
    base, by the options' rescue strategy. The trigger compares the two fits' delta-method errors
    without the between-run error: that spread is what the rescue repairs, and a rescue only adds
    an evidence that must beat the first, so firing more often costs simulations, never a name."""
    o = run.options
    strategy = RESCUES[o.rescue_method]
    rescuable = [
        n
        for n in st.chosen
        if (o.rescue_forward if get(n).kind == "forward" else o.rescue_observation)
        and not (o.rescue_method == "reference" and starts_from_base(o.refit_start, n))
    ]
    z0, s0 = float(st.base.log_evidence), float(st.base.log_evidence_se)
    due = []
    for j, name in enumerate(rescuable):
        z1, s1 = float(st.refits[name].log_evidence), float(st.refits[name].log_evidence_se)
        if math.isfinite(z1) and z1 >= z0 - max(o.min_gain, o.k_se * math.hypot(s0, s1)):
            continue
        due.append((name, stage_seed(o.seed, "rescue", j), z1, s1, int(st.refits[name].n_simulations)))
    together = None
    if strategy.refit_many is not None and len(due) > 1:
        t1 = time.perf_counter()
        run.track.at("rescue", "entries")
        together = strategy.refit_many(run, st, [(name, seed) for name, seed, *_ in due])
    for k, (name, seed, z1, s1, first_sims) in enumerate(due):
        if together is None:
            t1 = time.perf_counter()
            run.track.at("rescue", name)
            zb, sb, near = strategy.refit(run, st, name, seed)
        else:
            zb, sb, near = together[k]
        st.n_simulations += int(near.n_simulations)
        kept = keep_if_higher(run, st, name, near, zb, t1, **{strategy.tag: "base"}) is not None
        st.notes.append(
            f"rescue: the {name} refit ended at log Z {z1:.1f}, below the base's {z0:.1f}; refitted "
            f"{strategy.how}: log Z {strategy.relation} {zb:.1f} +- {sb:.1f}"
            + ("" if kept else " (not higher; the first refit is kept)")
        )
        if kept:
            st.after[name]["rescued"] = {
                "method": strategy.method,
                "first_log_evidence": z1,
                "first_log_evidence_se": s1,
                "first_n_simulations": first_sims,
                **strategy.record(near),
            }
