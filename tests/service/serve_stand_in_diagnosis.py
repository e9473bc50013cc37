"""``vfinfer serve`` whose diagnosis is a stand-in, for tests/service/test_restart_diagnosis.py, which runs it as
a process of its own and kills it: the stand-in is deterministic given its seed, evaluates batch after batch
through the service's map (so the diagnosis's store keeps every finished part), and takes a few seconds, so a
kill lands in the middle of it. Its figure is bytes made from its report."""

from __future__ import annotations

import functools
import sys
import time
from pathlib import Path

import numpy as np

BATCHES, PARTS, PAUSE_S = 24, 4, 0.25
ROW_SUM = functools.partial(np.sum, axis=1)  # picklable without this script on the workers' path


class _Report:
    def __init__(self, d: dict):
        self.d = d

    def to_dict(self) -> dict:
        return dict(self.d)


def diagnose(problem, *, map, seed: int = 0, progress=None, **settings):
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    total, n = 0.0, 0
    for b in range(BATCHES):
        # a batch function as the diagnosis gives its map: rows in, one log-likelihood per row out
        out = map(ROW_SUM, [rng.standard_normal((3, 2)) ** 2 for _ in range(PARTS)])
        total += float(sum(np.sum(getattr(o, "loglik", o)) for o in out))
        n += 3 * PARTS
        if progress is not None:
            progress(
                {
                    "stage": "base fit",
                    "entry": None,
                    "step": b + 1,
                    "steps": BATCHES,
                    "simulations": n,
                    "elapsed_s": time.perf_counter() - t0,
                }
            )
        time.sleep(PAUSE_S)
    wall = time.perf_counter() - t0
    return _Report(
        {
            "verdict": f"stand-in sum {total!r}",
            "winner": None,
            "n_simulations": n,
            "wall_s": wall,
            "base": {"sum": total, "n_observed": int(problem.obs_gaw.size), "wall_s": wall},
            "settings": {k: v for k, v in sorted(settings.items()) if k != "chunk_size"},
            "cost": {"by_stage": {"base fit": {"wall_s": wall, "simulations": n}}},
        }
    )


def plot_diagnosis(report, problem, path) -> None:
    Path(path).write_bytes(b"\x89PNG\r\n\x1a\n" + report.to_dict()["verdict"].encode())


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    import vfcore.diagnose.pipeline as P

    P.diagnose, P.plot_diagnosis = diagnose, plot_diagnosis
    from service.cli import main

    sys.exit(main())
