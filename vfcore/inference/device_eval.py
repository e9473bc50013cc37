"""Scoring a Problem's draws with the FE model on a chosen device (:func:`vfcore.batch.simulate_many`'s
``device``: "cpu", "cuda" or "auto"): the batch function a sampler or a worker chunk maps, as
:class:`vfcore.inference.problem.ProblemEvaluator` is on the CPU."""

from __future__ import annotations

import numpy as np

from vfcore.batch import LOCKSTEP_WIDTH

from .problem import Evaluation, Problem, score_results


class DeviceEvaluator:
    """Picklable batch function ``thetas -> Evaluation`` of ``problem`` with the FE rows simulated on ``device``.

    A row whose parameters are invalid scores as failed, as in :func:`vfcore.inference.problem.evaluate`.
    ``device="cuda"`` where no GPU can run the kernel raises :class:`vfcore.gpu.CudaUnavailable` (one line
    saying what is missing) on the first call.
    """

    def __init__(self, problem: Problem, device: str = "cpu"):
        self.problem = problem
        self.device = device

    def __call__(self, thetas) -> Evaluation:
        from vfcore.batch import simulate_many

        thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
        results: list = [None] * thetas.shape[0]
        params = []
        for i, th in enumerate(thetas):
            try:
                params.append((i, self.problem.prior.to_params(th)))
            except Exception as exc:  # noqa: BLE001 - reported per draw
                results[i] = exc
        if params:
            sims = simulate_many([p for _, p in params], self.problem.config, block=LOCKSTEP_WIDTH, device=self.device)
            for (i, _), r in zip(params, sims):
                results[i] = r
        return score_results(results, self.problem)
