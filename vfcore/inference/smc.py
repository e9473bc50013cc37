"""Likelihood-tempered sequential Monte Carlo (adaptive SMC sampler).

Targets the sequence ``pi_phi(theta) ∝ prior(theta) L(theta)^phi`` with ``0 = phi_0 < ... < phi_T = 1``
(Del Moral, Doucet & Jasra 2006; Chopin & Papaspiliopoulos 2020, ch. 17):

1. ``init_factor * N`` particles from the prior, each evaluated once (a larger first population
   sees more of a rugged likelihood's basins; the first reweighting resamples it down to ``N``,
   and the first evidence increment is the mean over all of them, so ``log Z`` stays unbiased).
2. Next temperature by bisection so that the effective sample size of the incremental
   weights ``L^(phi' - phi)`` equals ``ess_fraction * N``; evidence increment
   ``log mean_i L_i^(phi' - phi)``, ``log Z = sum`` of the increments (:mod:`.tempering`).
3. Systematic resampling to equal weights.
4. Metropolis moves targeting ``pi_phi'`` (:mod:`.moves`): a random walk (in ``theta`` or, with
   ``coords="log"``, in ``log theta``) with covariance ``scale^2 * Cov(particles)``, an independence
   proposal from the fitted Gaussian, or both alternating; proposals outside the prior box are rejected
   without a simulation. The scale is adapted towards ``target_acceptance`` and the number of
   moves per generation is chosen from the observed acceptance rate ``a`` so that a particle
   has moved with probability ``p_move``: ``n = ceil(log(1 - p_move) / log(1 - a))`` clipped to
   ``[min_moves, max_moves]``.
5. Repeat until ``phi = 1``; the final particles are an equally weighted posterior sample.

With ``symmetry=`` (a :class:`.symmetry.ScaleGroup`: a direction along which the log-likelihood is exactly
invariant, the model's common scale) the walk runs in log coordinates projected off that direction and every
move step ends with an exact group move along it, which needs no simulation (:mod:`.symmetry`).

With ``reference=q`` (:mod:`.reference`) the run starts from draws of ``q`` instead of the prior
and tempers ``q^(1 - phi) (p L)^phi`` (generalized stepping-stone path, Fan et al. 2011): the
reweighting uses ``log p + log L - log q`` in place of ``log L`` and the Metropolis ratio gains
``(1 - phi) (log q' - log q)``; ``log Z`` is still the evidence ``∫ p L`` (``q`` is normalised).
A ``q`` near the posterior starts the sampler in its mode instead of making it find the mode.

With ``delayed=True`` each Metropolis move is a two-stage delayed-acceptance move (Christen & Fox 2005;
:mod:`.moves`): a proposal is first screened with a cheap log-likelihood (``SMCSampler.stage == "screen"``; a
coarser mesh, a larger step) and only the survivors are simulated with the full model; the sampler's target,
its reweighting and its evidence stay the full model's. The initial population is evaluated with both.

The sampler is an ask/tell state machine (``SMCSampler.ask() -> thetas or None``,
``SMCSampler.tell(evaluation)``) so a distributed worker evaluates each batch itself; all
randomness comes from ``SeedSequence(seed, spawn_key=(generation, step, stream))``, so the run
is deterministic for a seed and independent of how batches were evaluated.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from .diagnostics import systematic_resample
from .importance import map_evaluate, resolve_target
from .moves import check_moves, delayed_log_acceptance, log_acceptance, moves_for, walk_cholesky
from .posterior import Posterior
from .prior import Prior
from .problem import Evaluation, Problem, model_record
from .smc_posterior import posterior_of
from .tempering import reweight

_INIT, _RESAMPLE, _MOVE, _ACCEPT, _FINAL, _GROUP = 0, 1, 2, 3, 4, 5

DEFAULT_PARTICLES = 300

#: options of :func:`smc` that act on a whole run, not on the sampler: runs made together
#: (:func:`smc_many`, :func:`run_together`) do not take them
WHOLE_RUN_OPTIONS = ("screen", "runs", "run_rule", "run_gap")


class SMCSampler:
    """Ask/tell likelihood-tempered SMC.

    >>> s = SMCSampler(prior, n_particles=300, seed=1)
    >>> while (thetas := s.ask()) is not None:
    ...     s.tell(batch_fn(thetas))          # Evaluation or array of log-likelihoods
    >>> post = s.result()
    """

    def __init__(
        self,
        prior: Prior,
        n_particles: int = DEFAULT_PARTICLES,
        seed: int = 0,
        *,
        ess_fraction: float = 0.5,
        target_acceptance: float = 0.3,
        p_move: float = 0.8,
        min_moves: int = 2,
        max_moves: int = 4,
        max_generations: int = 200,
        init_scale: float | None = None,
        kernel: str = "rw",
        independent_inflation: float = 1.5,
        init_factor: int = 1,
        reference=None,
        delayed: bool = False,
        coords: str | None = None,
        symmetry=None,
    ):
        if not isinstance(prior, Prior):
            raise ValueError("prior must be a Prior")
        if int(n_particles) < 10:
            raise ValueError(f"n_particles must be >= 10, got {n_particles}")
        if not 0.0 < ess_fraction < 1.0:
            raise ValueError(f"ess_fraction must lie in (0, 1), got {ess_fraction}")
        if not 0.0 < p_move < 1.0:
            raise ValueError(f"p_move must lie in (0, 1), got {p_move}")
        if not 1 <= int(min_moves) <= int(max_moves):
            raise ValueError("need 1 <= min_moves <= max_moves")
        if int(init_factor) < 1:
            raise ValueError(f"init_factor must be >= 1, got {init_factor}")
        self.init_factor = int(init_factor)
        if reference is not None and not (hasattr(reference, "sample") and hasattr(reference, "logpdf")):
            raise ValueError("reference must have sample(n, rng) and logpdf(thetas) (vfcore.inference.reference)")
        if reference is not None and getattr(reference, "prior", prior).ndim != prior.ndim:
            raise ValueError("the reference's prior has another number of dimensions than the sampler's")
        self.reference = reference
        self.delayed = bool(delayed)
        self.kernel = kernel
        self.coords = check_moves(kernel, coords, prior, reference, self.delayed, symmetry)
        self.symmetry = symmetry
        self._moves = moves_for(kernel, self.coords, independent_inflation)  # the proposals of even and odd steps
        self._log_jac: np.ndarray | None = None
        self.independent_inflation = float(independent_inflation)
        self.prior = prior
        self.n = int(n_particles)
        self.seed = int(seed)
        self.ess_fraction = float(ess_fraction)
        self.target_acceptance = float(target_acceptance)
        self.p_move = float(p_move)
        self.min_moves, self.max_moves = int(min_moves), int(max_moves)
        self.max_generations = int(max_generations)
        d_walk = prior.ndim - 1 if symmetry is not None else prior.ndim  # the group move samples the last one
        self.scale = float(init_scale) if init_scale is not None else 2.38 / math.sqrt(max(d_walk, 1))
        self.phi = 0.0
        self.generation = 0
        self.theta: np.ndarray | None = None
        self.ev: Evaluation | None = None
        self.log_evidence = 0.0
        self.log_evidence_var = float(getattr(reference, "log_norm_var", 0.0)) if reference is not None else 0.0
        self.n_simulations = 0
        self.n_failed = 0
        self.history: list[dict] = []
        self.last_ess = float(self.n)
        self._phase = "init"  # init -> move -> ... -> done
        self._pending: np.ndarray | None = None
        self._pending_idx: np.ndarray | None = None
        self._chol: np.ndarray | None = None
        self._mu: np.ndarray | None = None
        self._log_q_old: np.ndarray | None = None
        self._log_q_new: np.ndarray | None = None
        self._step = 0
        self._n_moves = self.max_moves
        self._gen_acc: list[float] = []
        self._gen_sims = 0
        # delayed acceptance: cheap log-likelihoods of the particles, the screening stage's state
        self.stage = "screen" if self.delayed else "full"
        self.ll_cheap: np.ndarray | None = None
        self._cheap_pending: np.ndarray | None = None
        self.n_screened = 0
        self.n_screen_rejected = 0

    # ------------------------------------------------------------------ randomness
    def _rng(self, stream: int, step: int = 0) -> np.random.Generator:
        ss = np.random.SeedSequence(self.seed, spawn_key=(self.generation, step, stream))
        return np.random.default_rng(ss)

    @property
    def done(self) -> bool:
        return self._phase == "done"

    # ------------------------------------------------------------------ ask / tell
    def ask(self) -> np.ndarray | None:
        """The parameter vectors (k, d) to evaluate next, or None when finished.

        Calling ``ask`` again before ``tell`` returns the same batch."""
        if self._phase == "done":
            return None
        if self._pending is None:
            if self._phase == "init":
                m = self.n * self.init_factor
                src = self.prior if self.reference is None else self.reference
                self._pending = src.sample(m, self._rng(_INIT))
                self._pending_idx = np.arange(m)
            else:
                self._propose()
                while self._pending is not None and self._pending.shape[0] == 0:
                    # every proposal fell outside the prior: a step with no simulations
                    self._finish_move(np.zeros(self.n, bool))
                    if self._phase == "done":
                        return None
                    self._propose()
                if self.delayed:
                    self.stage = "screen"
        return self._pending

    def tell(self, evaluation) -> None:
        """Report the evaluation (Evaluation or log-likelihood array) of the last ``ask``."""
        if self._pending is None:
            raise RuntimeError("tell() without a pending ask()")
        ev = Evaluation.coerce(evaluation)
        if len(ev) != self._pending.shape[0]:
            raise ValueError(f"expected {self._pending.shape[0]} evaluations, got {len(ev)}")
        if self.stage == "screen":
            self._tell_screen(np.asarray(ev.loglik, dtype=float))
            return
        self.n_simulations += len(ev)
        self._gen_sims += len(ev)
        self.n_failed += ev.n_failed
        if self._phase == "init":
            self.theta = self._pending
            self.ev = ev
            if self.delayed:
                self.ll_cheap = self._cheap_pending
                self.stage = "screen"
            self._pending = self._pending_idx = None
            if not np.any(np.isfinite(ev.loglik)):
                raise RuntimeError("every initial simulation failed or had zero likelihood")
            self._advance()
            return
        if self.delayed:
            self._tell_full_delayed(ev)
            return
        # Metropolis accept/reject; uniform prior => ratio is the tempered likelihood ratio
        idx = self._pending_idx
        props = self._pending
        ref = None
        if self.reference is not None:  # pi_phi ∝ q^(1 - phi) (p L)^phi; p is flat on the box
            lq = self.reference.logpdf(np.concatenate([self.theta[idx], props]))
            with np.errstate(invalid="ignore"):
                ref = (1.0 - self.phi) * (lq[idx.size :] - lq[: idx.size])
        hastings = (self._log_q_old, self._log_q_new) if self._log_q_new is not None else None
        log_alpha = log_acceptance(
            self.phi, ev.loglik, self.ev.loglik[idx], reference=ref, log_q=hastings, log_jac=self._log_jac
        )
        u = self._rng(_ACCEPT, self._step).random(idx.size)
        acc = np.log(u) < log_alpha
        self._finish_move(self._accept(idx, props, acc, ev))

    def _accept(self, idx, props, acc, ev) -> np.ndarray:
        """Move the particles ``idx[acc]`` to their proposals (and evaluations); clear the pending batch.
        Returns the (n,) accepted mask."""
        accepted = np.zeros(self.n, bool)
        accepted[idx[acc]] = True
        th = self.theta.copy()
        th[idx[acc]] = props[acc]
        self.theta = th
        self.ev = self.ev.scatter(idx[acc], ev.take(np.flatnonzero(acc)))
        self._pending = self._pending_idx = None
        return accepted

    # ------------------------------------------------------------------ delayed acceptance
    def _tell_screen(self, ll_cheap: np.ndarray) -> None:
        """Stage 1: the cheap log-likelihoods of the pending batch (the initial population, or proposals)."""
        self.n_screened += ll_cheap.size
        if self._phase == "init":
            # the initial population's cheap values; the same draws then go to the full model
            self._cheap_pending = ll_cheap
            self.stage = "full"
            return
        idx, props = self._pending_idx, self._pending
        # the prior's part of the ratio (a log walk's Jacobian) belongs to the first stage
        log_a1 = log_acceptance(self.phi, ll_cheap, self.ll_cheap[idx], log_jac=self._log_jac)
        u = self._rng(_ACCEPT, 2 * self._step + 1).random(idx.size)
        keep = np.log(u) < log_a1
        self.n_screen_rejected += int(idx.size - keep.sum())
        self._screen_cheap = ll_cheap[keep]
        if self._log_jac is not None:
            self._log_jac = self._log_jac[keep]
        if not np.any(keep):
            self._pending = self._pending_idx = None
            self.stage = "screen"
            self._finish_move(np.zeros(self.n, bool))
            return
        self._pending = props[keep]
        self._pending_idx = idx[keep]
        self.stage = "full"

    def _tell_full_delayed(self, ev) -> None:
        """Stage 2: the full model decides with the ratio corrected by the cheap one (exact target)."""
        idx, props, lc_new = self._pending_idx, self._pending, self._screen_cheap
        log_a2 = delayed_log_acceptance(self.phi, ev.loglik, self.ev.loglik[idx], lc_new, self.ll_cheap[idx])
        u = self._rng(_ACCEPT, 2 * self._step + 2).random(idx.size)
        acc = np.log(u) < log_a2
        lc = self.ll_cheap.copy()
        lc[idx[acc]] = lc_new[acc]
        self.ll_cheap = lc
        self.stage = "screen"
        self._finish_move(self._accept(idx, props, acc, ev))

    # ------------------------------------------------------------------ internals
    def _advance(self) -> None:
        """Reweight to the next temperature, resample, prepare the moves (or finish)."""
        if self.phi >= 1.0:
            self._phase = "done"
            return
        if self.generation >= self.max_generations:
            raise RuntimeError(f"SMC did not reach phi = 1 in {self.max_generations} generations (phi={self.phi:.3g})")
        rw = reweight(self._bridge_loglik(), self.phi, self.ess_fraction)
        phi_new, w, inc = rw.phi, rw.weights, rw.log_evidence_increment
        self.log_evidence += inc
        self.log_evidence_var += rw.log_evidence_var
        self.last_ess = rw.ess
        self.generation += 1
        # the reweighted particles' Gaussian (in the walk's coordinates) -> the proposals
        span = np.log(self.prior.hi / self.prior.lo) if self.coords == "log" else self.prior.width
        direction = self.symmetry.direction if self.symmetry is not None else None
        self._mu, self._chol = walk_cholesky(self._walk_coords(self.theta), w, direction, span)
        idx = systematic_resample(w, self.n, self._rng(_RESAMPLE))
        self.theta = self.theta[idx]
        self.ev = self.ev.take(idx)
        if self.delayed:
            self.ll_cheap = self.ll_cheap[idx]
        self.history.append(
            {
                "generation": self.generation,
                "phi": phi_new,
                "ess": self.last_ess,
                "log_evidence_increment": inc,
                "n_unique_after_resample": int(np.unique(idx).size),
            }
        )
        self.phi = phi_new
        self._phase = "move"
        self._step = 0
        self._n_moves = self.max_moves
        self._gen_acc = []
        self._gen_sims = 0

    def _bridge_loglik(self) -> np.ndarray:
        """The log of what is tempered: ``log L`` from the prior, ``log p + log L - log q`` from a
        reference ``q`` (vfcore.inference.reference)."""
        ll = np.asarray(self.ev.loglik, dtype=float)
        if self.reference is None:
            return ll
        with np.errstate(invalid="ignore"):
            r = ll + self.prior.logpdf(self.theta) - self.reference.logpdf(self.theta)
        return np.where(np.isfinite(ll), r, -np.inf)

    def _walk_coords(self, theta: np.ndarray) -> np.ndarray:
        return np.log(theta) if self.coords == "log" else theta

    def _propose(self) -> None:
        rng = self._rng(_MOVE, self._step)
        z = rng.standard_normal((self.n, self.prior.ndim))
        move = self._moves[self._step % 2]
        prop = move.propose(self.theta, z, self.scale, self._chol, self._mu)
        inside = self.prior.contains(prop)
        self._pending_idx = np.flatnonzero(inside)
        self._pending = prop[inside]
        self._log_jac = move.log_jacobian(self._pending, self.theta[self._pending_idx])
        if move.independent:
            self._log_q_old = move.log_q(self.theta[self._pending_idx], self._mu, self._chol)
            self._log_q_new = move.log_q(self._pending, self._mu, self._chol)
        else:
            self._log_q_old = self._log_q_new = None

    def _group_move(self) -> None:
        """Move every particle along the symmetry's orbit by an exact draw (vfcore.inference.symmetry);
        no simulation: the waveforms stay, the products scale."""
        from .symmetry import move_particles

        self.theta, self.ev, d = move_particles(
            self.symmetry, self.theta, self.ev, self.phi, self._rng(_GROUP, self._step)
        )
        if self.delayed:
            self.ll_cheap = np.where(np.isfinite(self.ll_cheap), self.ll_cheap + d, self.ll_cheap)

    def _n_distinct(self) -> int:
        """Distinct particles, counted along what the walk explores (group moves make every particle's
        position along the orbit distinct without telling the data anything)."""
        if self.symmetry is None:
            return int(np.unique(self.theta, axis=0).shape[0])
        return self.symmetry.n_distinct(self.theta)

    def _finish_move(self, accepted: np.ndarray) -> None:
        if self.symmetry is not None:
            self._group_move()
        a = float(np.mean(accepted))
        self._gen_acc.append(a)
        self._step += 1
        if not self._moves[(self._step - 1) % 2].independent:
            # adapt the random-walk scale towards the target acceptance rate
            self.scale *= math.exp(2.0 * (a - self.target_acceptance))
            self.scale = min(max(self.scale, 1e-3), 10.0)
        if self._step == 1:
            a_eff = min(max(a, 1e-3), 0.999)
            n = math.ceil(math.log(1.0 - self.p_move) / math.log(1.0 - a_eff))
            self._n_moves = int(min(max(n, self.min_moves), self.max_moves))
        if self._step >= self._n_moves:
            h = self.history[-1]
            h.update(
                {
                    "moves": self._step,
                    "acceptance": float(np.mean(self._gen_acc)),
                    "scale": self.scale,
                    "n_simulations": self._gen_sims,
                    "n_unique_after_moves": self._n_distinct(),
                }
            )
            self._advance()

    # ------------------------------------------------------------------ result
    def result(self, *, obs_gaw=None, fps: float | None = None) -> Posterior:
        """The final particles as an equally weighted :class:`.posterior.Posterior` (:mod:`.smc_posterior`)."""
        if not self.done:
            raise RuntimeError("SMC has not finished (keep calling ask/tell)")
        rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(self.generation + 1, 0, _FINAL)))
        return posterior_of(self, rng, obs_gaw=obs_gaw, fps=fps)


def smc(
    target,
    prior: Prior | None = None,
    n_particles: int = DEFAULT_PARTICLES,
    seed: int = 0,
    *,
    map: Callable = map,
    chunk_size: int = 32,
    screen=None,
    symmetry: str | None = "auto",
    runs: int = 1,
    run_rule: str = "loglik",
    run_gap: float | None = None,
    **options,
) -> Posterior:
    """Run likelihood-tempered SMC to completion.

    ``target``: a ``Problem`` or a callable ``thetas (k, d) -> loglik (k,)`` (then ``prior`` is
    required). ``screen``: a cheaper target of the same kind (e.g. the Problem on a coarser mesh or
    step) for delayed-acceptance moves (``SMCSampler(delayed=True)``); the posterior remains the
    full target's. ``symmetry="auto"``: when ``target`` is a Problem that estimates all six parameters of the
    common scale, the walk runs in their log-ratios and the scale is drawn exactly by group moves
    (:mod:`.symmetry`); None turns that off. Options go to ``SMCSampler``. Returns a Posterior with ``n_simulations`` counted
    (full-model simulations; ``info["n_screened"]`` counts the cheap ones) and ``log_evidence`` (its
    ``log_evidence_se`` is the delta-method error summed over generations, ignoring the particle
    dependence: a rough lower bound).

    ``runs`` > 1: that many independent runs (seeds :func:`.runs.run_seeds`; the first is this seed's own run),
    pooled by :func:`.runs.pool_runs` (runs whose best particle's log-likelihood, or with ``run_rule="evidence"``
    whose log evidence, lies more than ``run_gap`` nats below the best run's are left out, the others sharing the
    posterior equally); ``info["runs"]`` lists them.
    """
    if int(runs) != 1:
        from .runs import pool_runs, run_seeds

        seeds = run_seeds(seed, runs)
        posts = [
            smc(
                target,
                prior,
                n_particles,
                s,
                map=map,
                chunk_size=chunk_size,
                screen=screen,
                symmetry=symmetry,
                **options,
            )
            for s in seeds
        ]
        return pool_runs(posts, seed=seed, rule=run_rule, gap=run_gap)
    prior, obs, fps, fn = resolve_target(target, prior)
    cheap = resolve_target(screen, prior)[3] if screen is not None else None
    group = _scale_group(target, prior, symmetry)
    sampler = SMCSampler(prior, n_particles, seed, delayed=cheap is not None, symmetry=group, **options)
    while (th := sampler.ask()) is not None:
        f = cheap if sampler.stage == "screen" else fn
        sampler.tell(map_evaluate(f, th, map=map, chunk_size=chunk_size))
    return _finished(sampler, target, obs, fps)


def _scale_group(target, prior: Prior, symmetry: str | None):
    """The exact scale symmetry the walk uses (``symmetry="auto"``, a Problem estimating all six), or None."""
    if symmetry not in ("auto", None):
        raise ValueError(f"symmetry must be 'auto' or None, got {symmetry!r}")
    if symmetry == "auto" and isinstance(target, Problem) and prior.names == target.prior.names:
        from .symmetry import scale_group

        return scale_group(target)
    return None


def _finished(sampler: SMCSampler, target, obs, fps) -> Posterior:
    post = sampler.result(obs_gaw=obs, fps=fps)
    post.area_scale = getattr(target, "area_scale", None) if isinstance(target, Problem) else None
    post.model = model_record(target)
    return post


def run_together(samplers: list, evaluate: Callable, on_done: Callable[[int], None]) -> None:
    """Advance ``samplers`` (:class:`SMCSampler`) together to the end: at each round every unfinished
    sampler's pending batch, as ``(i, thetas)`` pairs, goes to ``evaluate`` in one call, which returns one
    Evaluation per pair; ``on_done(i)`` as sampler ``i`` finishes. Each sampler's run is the one it makes
    alone: its randomness is its own seed's, and its batches are the ones it asks for."""
    done = [False] * len(samplers)
    while True:
        pending = []
        for i, s in enumerate(samplers):
            if done[i]:
                continue
            th = s.ask()
            if th is None:
                done[i] = True
                on_done(i)
                continue
            pending.append((i, th))
        if not pending:
            return
        evs = evaluate(pending)
        if len(evs) != len(pending):
            raise RuntimeError(f"{len(evs)} evaluations for {len(pending)} batches")
        for (i, _), ev in zip(pending, evs):
            samplers[i].tell(ev)


def smc_many(
    target,
    jobs,
    prior: Prior | None = None,
    *,
    map: Callable = map,
    chunk_size: int = 32,
    symmetry: str | None = "auto",
    on_done: Callable[[int, Posterior], None] | None = None,
    **options,
) -> list[Posterior]:
    """Several runs of :func:`smc` on one target (``jobs``: ``(n_particles, seed)`` each), run together
    (:func:`run_together`): at each round the pending batch of every unfinished run goes to ``map`` as one
    batch, so a worker's lock-step blocks are wider (:ref:`validation-model-speed`) and a cluster has every run's
    rows at once. Each posterior equals ``smc(target, prior, n_particles, seed, ...)`` alone, bit for bit.
    ``on_done(i, posterior)`` as run ``i`` finishes. ``options`` are the sampler's
    (:class:`SMCSampler`); a cheaper ``screen`` target and pooled ``runs`` are :func:`smc`'s only."""
    bad = sorted(set(options) & set(WHOLE_RUN_OPTIONS))
    if bad:
        raise ValueError(f"runs made together take the sampler's options only; not {bad}")
    prior, obs, fps, fn = resolve_target(target, prior)
    group = _scale_group(target, prior, symmetry)
    samplers = [SMCSampler(prior, int(n), int(s), symmetry=group, **options) for n, s in jobs]
    posts: list = [None] * len(samplers)

    def evaluate(pending):
        ev = map_evaluate(fn, np.concatenate([th for _, th in pending]), map=map, chunk_size=chunk_size)
        edges = np.cumsum([0] + [th.shape[0] for _, th in pending])
        return [ev.take(np.arange(a, b)) for a, b in zip(edges[:-1], edges[1:])]

    def finish(i):
        posts[i] = _finished(samplers[i], target, obs, fps)
        if on_done is not None:
            on_done(i, posts[i])

    run_together(samplers, evaluate, finish)
    return posts
