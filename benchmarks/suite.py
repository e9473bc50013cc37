"""Reading a concealed-effect suite (``benchmarks/concealed/generate.py``) into fitting problems.

Shared by the benchmark scripts that fit a suite's cases (``bench_diagnose.py``,
``bench_halving.py``, ``bench_refits.py``, ``bench_integrated.py``, ``oracle_check.py``). Only the PUBLIC ``cases.json`` and the recordings are
read here; ``truth.json`` is the scorer's alone.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def one_case(cases_dir, case_id: str) -> tuple[dict, dict]:
    """``(meta, case)`` of case ``case_id`` of the suite in ``cases_dir`` (its ``cases.json``);
    ValueError (one line) when the suite has no such case."""
    cases_dir = Path(cases_dir)
    meta = json.loads((cases_dir / "cases.json").read_text())
    by_id = {c["id"]: c for c in meta["cases"]}
    if case_id not in by_id:
        raise ValueError(f"no case {case_id!r} in {cases_dir / 'cases.json'}")
    return meta, by_id[case_id]


def case_problem(
    meta: dict,
    case: dict,
    cases_dir: Path,
    duration: float | None,
    sigma_e: float,
    discard: float | None = None,
    noise: str = "fixed",
    lag_search: str = "window",
):
    """The fitting problem of one case: its GAW and fps, the default prior with the suite's fixed
    parameters, and the suite's public forward-model settings (``cases.json`` "model"); ``duration``
    and ``discard`` override the simulated window when given."""
    from vfcore.config import SimConfig
    from vfcore.inference import Prior
    from vfcore.inference.problem import Problem

    m = meta["model"]
    cfg = SimConfig(
        mesh=m["mesh"],
        dt=m["dt"],
        duration=m["duration"] if duration is None else duration,
        discard=m["discard"] if discard is None else discard,
        fps=case["fps"],
    )
    prior = Prior.default(fixed=meta["fixed"])
    y = np.loadtxt(Path(cases_dir) / case["file"], delimiter=",", skiprows=1, ndmin=1)
    return Problem(y, case["fps"], prior, sigma_e=sigma_e, config=cfg, noise=noise, lag_search=lag_search)
