"""Seeds of a diagnosis's stages, drawn from the run's ``numpy.random.SeedSequence``.

Every stage (and every entry or attempt within one) takes the child ``SeedSequence(seed).spawn(...)`` at its
own key, ``SeedSequence(seed, spawn_key=(stage, index, ...))``: the streams of two stages never coincide,
whatever the run seed, where seeds made by adding offsets to the run seed collide as soon as two offsets differ
by a multiple of a stride. A child's integer seed is its first 32-bit word, so the samplers, the Sobol designs
and the regularity check take it as the plain ``int`` seed they already take.
"""

from __future__ import annotations

import numpy as np

__all__ = ["STAGES", "spawn_seed", "stage_seed"]

#: The stages with a stream of their own; a stage's key is its position here, so append, never reorder.
STAGES = (
    "base",
    "regularity",
    "screen",
    "refit",
    "rescue",
    "shared_mode",
    "mode_check",
    "mode_check_continued",
    "nested_check",
    "continuation",
)


def spawn_seed(seed: int, *key: int) -> int:
    """The integer seed of the child of ``SeedSequence(seed)`` at spawn key ``key``; a 32-bit integer."""
    ss = np.random.SeedSequence(int(seed), spawn_key=tuple(int(k) for k in key))
    return int(ss.generate_state(1, dtype=np.uint32)[0])


def stage_seed(seed: int, stage: str, *index: int) -> int:
    """The seed of ``stage`` (one of :data:`STAGES`), and of its entry or attempt ``index``, in a diagnosis
    run with seed ``seed``."""
    return spawn_seed(seed, STAGES.index(stage), *index)
