"""The shared mode: every refitted entry gets a second SMC started from the leading refit's material mode,
so that every entry is compared in the best material mode any of them found (:ref:`diagnose-pipeline`,
"Shared mode"; ``DiagnoseOptions.shared_mode``, off by default)."""

from __future__ import annotations

import math
import time

from .mode_fits import shared_mode_refit
from .refits import keep_if_higher
from .seeds import stage_seed
from .state import DiagnosisState, Run

__all__ = ["shared_mode_leader", "refit_from_leader"]


def shared_mode_leader(
    base_logz: float, after: dict, refits: dict, base_rms: float, *, min_gain: float, min_rms_gain: float
) -> str | None:
    """The refit whose material mode the others are refitted from (:func:`diagnose`,
    ``shared_mode``): the largest log-evidence among the refits that are not null-consistent, beat
    the base by more than ``min_gain`` and remove at least ``min_rms_gain`` of its residual RMS;
    ``None`` when no refit qualifies."""
    best, best_z = None, -math.inf
    for name, post in refits.items():
        s = after.get(name, {})
        z = float(post.log_evidence)
        if not math.isfinite(z) or s.get("null_consistent", True):
            continue
        if z - base_logz <= min_gain or 1.0 - s.get("residual_rms", math.inf) / base_rms < min_rms_gain:
            continue
        if z > best_z:
            best, best_z = name, z
    return best


def refit_from_leader(run: Run, st: DiagnosisState) -> None:
    """Every other refitted entry refitted from the leader's material mode, the new fit kept when
    its evidence is larger; the leader is recorded as ``st.before["shared_mode_leader"]``."""
    if not st.refits:
        return
    o = run.options
    leader = shared_mode_leader(
        float(st.base.log_evidence),
        st.after,
        st.refits,
        st.before["residual_rms"],
        min_gain=o.min_gain,
        min_rms_gain=o.min_rms_gain,
    )
    if leader is None:
        return
    lead_post = st.refits[leader]
    for j, name in enumerate(n for n in st.chosen if n != leader and n in st.refits):
        t1 = time.perf_counter()
        run.track.at("shared mode", name)
        z1 = float(st.refits[name].log_evidence)
        zb, sb, near = shared_mode_refit(
            st.problem,
            lead_post,
            name,
            n_particles=st.refit_n,
            seed=stage_seed(o.seed, "shared_mode", j),
            map=run.map,
            chunk_size=o.chunk_size,
            inflate=o.rescue_inflate,
            integrate=o.integrate,
            **run.smc,
        )
        st.n_simulations += int(near.n_simulations)
        kept = (
            keep_if_higher(run, st, name, near, zb, t1, record=("shared_mode", {"from": leader}), shared_mode_of=leader)
            is not None
        )
        st.notes.append(
            f"shared mode: {name} refitted from {leader}'s material mode: log Z {zb:.1f} +- {sb:.1f} "
            f"against its first {z1:.1f}" + (" (kept)" if kept else " (not higher; the first is kept)")
        )
    st.before["shared_mode_leader"] = leader
