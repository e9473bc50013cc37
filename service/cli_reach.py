"""The reach ensemble of ``vfinfer infer`` on first use: found (shipped or cached) or built now, and said which.

A recording is checked against a reach ensemble of its configuration before a fit (docs/inference.md, "The
model's reach"). Ensembles ship for the command line's default configurations only; for another (the paper's
medium mesh, a new time step or contact law) the first run builds one and caches it, so that every later run
checks at once."""

from __future__ import annotations

import os
import time

from rich.console import Console

from .cli_common import ProgressLines, warn

console = Console()

#: Core-seconds per prior draw of a reach ensemble (dt 5e-5 s, 0.55 s simulated), measured: 128 draws of each
#: prior set at 56-68 ms a draw on the coarse mesh and 68 ms on the medium with the cores to themselves, and the
#: whole 2,000-draw medium-mesh build of `vfinfer infer --mesh medium --fix x0=8.4` in 254 s on 2 workers with
#: the 2 cores shared with other jobs (0.25 s a draw). The estimate takes the busy figure, an upper bound; most
#: draws do not phonate and stop early, which is why the medium mesh costs about what the coarse does.
REACH_S_PER_DRAW = {"coarse": 0.25, "medium": 0.25}


def ensure_reach(spec, workers: int) -> str | None:
    """Which reach ensemble the check of ``spec`` uses, in words: shipped, cached (built earlier) or built now
    (None: none, or not the FE model). With none for the job's configuration, build one on first use:
    ``DEFAULT_N`` draws of the job's prior set (:func:`vfcore.inference.reach.first_use_prior`) on ``workers``
    processes, with a progress line, cached in the user cache (``VFINFER_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/vfinfer``) under the key of every waveform-changing setting; ``VFINFER_REACH_BUILD=0``
    skips the build (the check then says it was not made)."""
    from vfcore.inference import reach as rc
    from vfcore.inference.prior import Prior as PriorBox

    if spec.model != "fe":
        return None
    cfg, prior = spec.sim_config(), spec.to_prior()
    ens, _ = rc.find_ensemble(cfg, prior)
    if ens is not None:
        return f"{rc.origin(ens)} ensemble of {ens.n} draws, {ens.source}"
    if os.environ.get("VFINFER_REACH_BUILD", "1").strip() == "0":
        return None
    target = rc.first_use_prior(prior, PriorBox.default(prior_set=spec.prior_set))
    n = rc.DEFAULT_N
    guess = n * REACH_S_PER_DRAW.get(cfg.mesh, 4 * REACH_S_PER_DRAW["medium"]) * (5e-5 / cfg.dt) / workers / 60.0
    path = rc.ensemble_path(rc.reach_key(cfg, target))
    console.print(
        f"reach: no ensemble for this configuration yet; building one now: {n} prior draws, about "
        f"{guess:.0f} min on {workers} worker{'s' if workers > 1 else ''} at most (measured: 2,000 medium-mesh "
        f"draws at dt 5e-5 s in 4 min 14 s on 2 busy workers), cached in {path} for later runs "
        "(VFINFER_REACH_BUILD=0 skips it)",
        highlight=False,
        soft_wrap=True,
    )
    t0 = time.perf_counter()
    with ProgressLines() as lines, _draw_map(workers) as simulate:

        def progress(done, total, el):
            lines.update("reach ensemble", done, total)

        ens = rc.build_ensemble(
            cfg,
            target,
            n,
            rc.DEFAULT_SEED,
            block=32 * workers,
            progress=progress,
            simulate_fn=simulate,
            on_error=lambda m: warn(f"reach ensemble: {m}"),
        )
    rc.save_cached(ens)
    console.print(
        f"reach: built now: {ens.n} draws in {time.perf_counter() - t0:.0f} s, cached in {path}",
        highlight=False,
        soft_wrap=True,
    )
    return f"built now, {path}"


class _draw_map:
    """``simulate_fn`` of :func:`vfcore.inference.reach.build_ensemble` that splits each block of draws over
    ``workers`` processes (in this process for one)."""

    def __init__(self, workers: int):
        self.workers, self.pool = workers, None

    def __enter__(self):
        if self.workers > 1:
            from concurrent.futures import ProcessPoolExecutor

            self.pool = ProcessPoolExecutor(self.workers)
        return self

    def __exit__(self, *exc):
        if self.pool is not None:
            self.pool.shutdown(cancel_futures=True)

    def __call__(self, rows, config, block):
        import numpy as np

        from vfcore.batch import simulate_many

        if self.pool is None:
            return simulate_many(rows, config, block=block)
        parts = [p for p in np.array_split(rows, self.workers) if len(p)]
        return [r for part in self.pool.map(simulate_many, parts, [config] * len(parts)) for r in part]
