"""Run a job on a Dask cluster: chunks of forward simulations, each writing its own store region.

* IS: ``draw_prior(prior, N, seed)`` -> batch 0 -> chunks -> ``reduce_importance`` (reducer task).
* SMC: vfcore's ask/tell ``SMCSampler`` is driven here; every ``ask()`` is one batch, evaluated
  in chunks exactly like IS; ``tell()`` gets the batch read back from the store.

Chunks are pure functions of (thetas, problem): their Dask keys are derived from the job id,
batch and chunk index, so a chunk lost with a worker is recomputed by the scheduler and writes
the same bytes.  On resume (service restart) every batch whose ``done`` mask is complete is
read from the store instead of recomputed, and only missing chunks are submitted; the SMC
sampler is replayed deterministically from the stored log-likelihoods.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.special import logsumexp

from vfcore.inference.diagnostics import ess_from_logsums
from vfcore.inference.importance import draw_prior
from vfcore.inference.problem import Evaluation, Problem

from . import store as st
from .jobspec import ISSettings, JobSpec, SMCSettings
from .models import job_device, model_named

#: Wall time one chunk should take (seconds): long enough that scheduling overhead (~ms per
#: task) is < 1 %, short enough that a lost worker costs little and progress stays live.
TARGET_CHUNK_SECONDS = 4.0
MIN_CHUNKS = 16


class JobCancelled(Exception):
    pass


def warm_up() -> None:
    """Import and JIT-compile what a reducer needs (arviz, matplotlib, numba ufuncs: ~2 s per process)
    once, when a worker starts, instead of inside the first job's critical path."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot  # noqa: F401

    from vfcore.inference.diagnostics import pareto_k

    pareto_k(np.log(np.linspace(1.0, 2.0, 64)))
    from . import reduce  # noqa: F401


try:
    from distributed.diagnostics.plugin import WorkerPlugin
except ImportError:  # pragma: no cover
    WorkerPlugin = object


class WarmUpPlugin(WorkerPlugin):
    """Runs ``warm_up`` on every worker, including workers that join or restart later."""

    name = "vfinfer-warm-up"

    async def setup(self, worker) -> None:
        # compiling takes seconds: off the worker's event loop, which must keep answering the scheduler
        import asyncio

        try:
            await asyncio.to_thread(warm_up)
        except Exception:  # noqa: BLE001 - warming is an optimisation only
            pass


def register_warm_up(client) -> None:
    try:
        client.register_plugin(WarmUpPlugin(), name=WarmUpPlugin.name)
    except Exception:  # noqa: BLE001
        pass


def estimated_seconds_per_sim(spec: JobSpec) -> float:
    return model_named(spec.model).seconds_per_sim(spec)


#: The FE evaluator's lock-step block (vfcore.batch.simulate_many): a chunk smaller than it runs narrower
#: blocks (medium mesh, phonating draws: 83 ms per simulation in blocks of 13, 66 ms in blocks of 32).
LOCKSTEP_BLOCK = 32


#: SMC simulations per particle over a whole run (initial population, every move of every generation),
#: the range measured on FE fits of 2 to 6 free parameters (:ref:`inference-samplers-cost-before-a-run`).
SMC_SIMS_PER_PARTICLE = (20, 90)


def probe_seconds_per_sim(spec: JobSpec, n: int = 32, seconds: float = 0.1) -> float:
    """Seconds per simulation of this job's model on this machine: ``n`` prior draws simulated in one
    lock-step block for ``seconds`` of model time, scaled to the job's duration
    (:func:`vfcore.batch.probe_seconds_per_sim`; a settled draw that stops early costs less, one that fails
    less still)."""
    if spec.model != "fe":
        return estimated_seconds_per_sim(spec)
    from vfcore.batch import probe_seconds_per_sim as probe

    problem_prior = spec.to_prior()
    rows = problem_prior.full_array(draw_prior(problem_prior, n, spec.seed))
    return probe(rows, spec.sim_config(), seconds)


def expected_simulations(spec: JobSpec) -> tuple[int, int]:
    """(low, high) number of simulations of the run: exact for IS, the measured range for SMC."""
    if isinstance(spec.sampler, ISSettings):
        return spec.sampler.n_samples, spec.sampler.n_samples
    lo, hi = SMC_SIMS_PER_PARTICLE
    n = spec.sampler.n_particles * spec.sampler.runs
    return lo * n, hi * n


#: Simulations per task on a GPU worker: one launch of one thread per simulation needs thousands of them to
#: keep the device busy (:ref:`gpu`).
GPU_CHUNK = 4096


def chunk_size_for(spec: JobSpec) -> int:
    """Simulations per task; a function of the spec only (it fixes the store's chunking). At least one
    lock-step block of the FE model unless the batch is smaller: a narrower chunk costs more per
    simulation than the finer load balance gains; on a GPU, at least :data:`GPU_CHUNK`."""
    if spec.chunk_size:
        return int(spec.chunk_size)
    by_time = max(1, int(TARGET_CHUNK_SECONDS / estimated_seconds_per_sim(spec)))
    by_count = max(1, -(-spec.n_simulations // MIN_CHUNKS))
    size = min(by_time, by_count, 10_000)
    if spec.model == "fe":
        size = max(size, min(LOCKSTEP_BLOCK, spec.n_simulations))
        if job_device(spec) == "cuda":
            size = max(size, min(GPU_CHUNK, spec.n_simulations))
    return int(size)


def cluster_threads(client) -> int:
    """Worker threads of the cluster (at least 1; 1 without a client)."""
    if client is None:
        return 1
    try:
        return max(1, sum(int(n) for n in client.nthreads().values()))
    except Exception:  # noqa: BLE001 - only used to size chunks
        return 1


def generation_chunk(spec: JobSpec, n: int, client) -> int | None:
    """Rows per chunk of an SMC generation of ``n`` rows: one equal share per worker thread of the cluster
    as it is when the batch is created (the batch keeps it, so a resume reads the same chunks), or None for
    the job's fixed chunk size (a spec that sets ``chunk_size``; a GPU job, whose launch wants every row).
    Why: a generation is small (100 particles), and fixed chunks of 32 go out as 32 + 32 + 32 + 4, so on 2
    workers one does 64 rows while the other does 36; equal shares finish together, each one wider
    lock-step block. A row's result does not depend on its neighbours, so no number changes."""
    if spec.chunk_size or (spec.model == "fe" and job_device(spec) == "cuda"):
        return None
    return max(1, -(-int(n) // cluster_threads(client)))


def evaluator_for(spec: JobSpec, problem: Problem) -> Callable[[np.ndarray], Evaluation]:
    """The job's model as a picklable batch function ``thetas (k, d) -> Evaluation`` (worker.models)."""
    return model_named(spec.model).evaluator(spec, problem)


def run_chunk(c: int, lo: int, thetas: np.ndarray, *, store_path: str, b: int, evaluator) -> np.ndarray:
    """Worker task: evaluate one chunk, write its region of batch ``b``, mark it done."""
    ev = evaluator(thetas)
    st.write_chunk(store_path, b, c, lo, ev)
    return np.asarray(ev.loglik, dtype=float)


class RunningESS:
    """ESS of the self-normalised IS weights over the log-likelihoods seen so far, O(chunk) per update."""

    def __init__(self) -> None:
        self.lse1 = -math.inf
        self.lse2 = -math.inf

    def add(self, loglik: np.ndarray) -> float:
        ll = np.asarray(loglik, dtype=float)
        ll = ll[np.isfinite(ll)]
        if ll.size:
            self.lse1 = float(np.logaddexp(self.lse1, logsumexp(ll)))
            self.lse2 = float(np.logaddexp(self.lse2, logsumexp(2.0 * ll)))
        return self.value

    @property
    def value(self) -> float:
        return 0.0 if self.lse1 == -math.inf else ess_from_logsums(self.lse1, self.lse2)


@dataclass
class JobControl:
    """Shared between the runner thread and whoever may cancel it (service DELETE)."""

    cancelled: threading.Event = field(default_factory=threading.Event)
    futures: list = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)
    client: object | None = None

    def cancel(self) -> None:
        self.cancelled.set()
        with self.lock:
            futs = list(self.futures)
        if futs and self.client is not None:
            try:
                self.client.cancel(futs, force=True)
            except Exception:  # noqa: BLE001 - best effort; the runner also checks the flag
                pass


@dataclass
class Progress:
    n_done: int = 0  # simulations finished (this run + already in the store)
    n_total: int = 0  # simulations known so far (IS: N; SMC: grows per generation)
    ess: float = float("nan")
    chunks_computed: int = 0
    chunks_skipped: int = 0
    generation: int = 0
    phase: str = "simulating"


def _run_batch(
    client,
    root,
    store_path: str,
    job_id: str,
    b: int,
    thetas: np.ndarray,
    evaluator,
    prog: Progress,
    report: Callable[[Progress], None],
    control: JobControl,
    seen_ll: RunningESS | None = None,
    chunk_size: int | None = None,
) -> Evaluation:
    from distributed import as_completed

    g = st.ensure_batch(root, b, thetas, chunk_size)
    cs = int(g.attrs["chunk_size"])
    n_chunks = int(g.attrs["n_chunks"])
    n = thetas.shape[0]
    done = st.done_mask(g)
    todo = [c for c in range(n_chunks) if not done[c]]
    skipped = n_chunks - len(todo)
    prog.chunks_skipped += skipped
    already = sum(min(cs, n - c * cs) for c in range(n_chunks) if done[c])
    prog.n_done += already
    if skipped and seen_ll is not None:
        ll = g["loglik"][...]
        prog.ess = seen_ll.add(ll[np.repeat(done, cs)[:n]])
    report(prog)
    if todo:
        if control.cancelled.is_set():
            raise JobCancelled()
        keys = [f"vfchunk-{job_id}-b{b}-c{c}" for c in todo]
        futs = client.map(
            run_chunk,
            todo,
            [c * cs for c in todo],
            [thetas[c * cs : (c + 1) * cs] for c in todo],
            key=keys,
            pure=True,
            store_path=str(store_path),
            b=b,
            evaluator=evaluator,
        )
        with control.lock:
            control.futures = list(futs)
        try:
            for fut in as_completed(futs, loop=client.loop):
                if control.cancelled.is_set():
                    raise JobCancelled()
                if fut.cancelled():
                    raise JobCancelled()
                ll = fut.result()
                prog.n_done += ll.size
                prog.chunks_computed += 1
                if seen_ll is not None:
                    prog.ess = seen_ll.add(ll)
                report(prog)
        except BaseException:
            client.cancel(futs, force=True)
            raise
        finally:
            with control.lock:
                control.futures = []
            del futs
    # the reducer / sampler read what the store holds (the same bytes whether or not recomputed)
    done = st.done_mask(g)
    if not done.all():
        raise RuntimeError(f"batch {b}: {int((~done).sum())} chunk(s) not written")
    return st.read_evaluation(g)


def prepare(store_path: Path, job_id: str, spec: JobSpec):
    """Create the store (idempotent); return (root, problem)."""
    problem = spec.to_problem()
    root = st.create_job_store(
        store_path, job_id, spec.to_json(), chunk_size_for(spec), problem.n_compare, problem.prior.ndim
    )
    return root, problem


def run_job(
    client,
    job_id: str,
    store_path: Path,
    spec: JobSpec,
    *,
    report: Callable[[Progress], None] | None = None,
    control: JobControl | None = None,
) -> dict:
    """Run (or resume) a job to completion; publish the posterior into the store.

    Returns timing and chunk statistics. Raises JobCancelled when cancelled.
    """
    report = report or (lambda p: None)
    control = control or JobControl()
    control.client = client
    t0 = time.perf_counter()
    root, problem = prepare(store_path, job_id, spec)
    evaluator = evaluator_for(spec, problem)
    prog = Progress()
    sp = str(store_path)
    if isinstance(spec.sampler, ISSettings):
        thetas = draw_prior(problem.prior, spec.sampler.n_samples, spec.seed)
        prog.n_total = thetas.shape[0]
        _run_batch(client, root, sp, job_id, 0, thetas, evaluator, prog, report, control, seen_ll=RunningESS())
        t_sim = time.perf_counter() - t0
        prog.phase = "reducing"
        report(prog)
        from .reduce import reduce_is_job

        fut = client.submit(reduce_is_job, sp, key=f"vfreduce-{job_id}", pure=True)
    elif isinstance(spec.sampler, SMCSettings):
        from vfcore.inference.smc import SMCSampler

        s = spec.sampler
        screen = None
        if s.screen is not None:
            # the same problem on the screening model's mesh and step (same observation and compared window)
            import dataclasses

            cheap = dataclasses.replace(problem, config=problem.config.replace(mesh=s.screen.mesh, dt=s.screen.dt))
            screen = evaluator_for(spec, cheap)
        from vfcore.inference.runs import pool_runs, run_seeds
        from vfcore.inference.symmetry import scale_group

        b, posts = 0, []
        # independent runs one after another; their batches are numbered on, so a resumed job reads them all back
        for seed in run_seeds(spec.seed, s.runs):
            # all six scaled parameters estimated: walk their log-ratios, draw the common scale exactly
            sampler = SMCSampler(
                problem.prior,
                s.n_particles,
                seed,
                delayed=screen is not None,
                symmetry=scale_group(problem),
                **s.sampler_options(),
            )
            while (th := sampler.ask()) is not None:
                if control.cancelled.is_set():
                    raise JobCancelled()
                prog.n_total += th.shape[0]
                prog.generation = sampler.generation
                fn = screen if sampler.stage == "screen" else evaluator
                ev = _run_batch(
                    client,
                    root,
                    sp,
                    job_id,
                    b,
                    th,
                    fn,
                    prog,
                    report,
                    control,
                    chunk_size=generation_chunk(spec, th.shape[0], client),
                )
                sampler.tell(ev)
                prog.ess = float(sampler.last_ess)
                b += 1
            posts.append(sampler.result(obs_gaw=problem.obs_compared, fps=problem.fps))
        t_sim = time.perf_counter() - t0
        prog.phase = "reducing"
        report(prog)
        post = posts[0] if len(posts) == 1 else pool_runs(posts, seed=spec.seed)
        from .reduce import publish_posterior

        fut = client.submit(publish_posterior, sp, post, key=f"vfreduce-{job_id}", pure=True)
    else:  # pragma: no cover
        raise ValueError("unknown sampler")
    with control.lock:
        control.futures = [fut]
    try:
        summary = fut.result()
    finally:
        with control.lock:
            control.futures = []
    if control.cancelled.is_set():
        raise JobCancelled()
    prog.phase = "done"
    prog.ess = float(summary.get("ess", prog.ess))
    report(prog)
    t_total = time.perf_counter() - t0
    return {
        "simulate_s": t_sim,
        "reduce_s": t_total - t_sim,
        "total_s": t_total,
        "chunks_computed": prog.chunks_computed,
        "chunks_skipped": prog.chunks_skipped,
        "n_simulations": prog.n_done,
        "ess": prog.ess,
    }
