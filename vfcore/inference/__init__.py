"""Bayesian inference of vocal-fold parameters (Hadwin et al. 2019, Section 4).

Free of Dask/FastAPI: parallelism is passed in as a ``map``-like callable.
"""

from .diagnostics import (
    PARETO_K_THRESHOLD,
    DegenerateEnsembleWarning,
    ess,
    log_evidence_is,
    normalize_log_weights,
    pareto_k,
    systematic_resample,
    weighted_quantiles,
)
from .identify import SCALED, Identifiability, format_identifiability, identify
from .importance import (
    DEFAULT_DRAWS,
    batch_function,
    chunks,
    draw_prior,
    importance_sample,
    map_evaluate,
    reduce_importance,
)
from .posterior import QUANTILE_LEVELS, Posterior
from .prior import TABLE2_BOUNDS, Prior
from .problem import (
    NOISE_MODELS,
    Evaluation,
    Problem,
    ProblemEvaluator,
    evaluate,
    gaussian_loglik,
    gaussian_measurement_loglik,
    marginal_gaussian_loglik,
    n_sim_frames,
    validate_measurements,
    validate_observation,
)
from .products import compare, flow_contact_table, plot_marginals, plot_predictive, predictive_bands
from .runs import RUN_GAP, pool_runs, run_seeds
from .sensitivity import dt_mesh_configs, ensemble_size_study, numerics_study, write_table
from .smc import DEFAULT_PARTICLES, SMCSampler, smc
from .tempering import next_temperature
from .twin import Twin, make_twin

__all__ = [
    "PARETO_K_THRESHOLD",
    "DegenerateEnsembleWarning",
    "ess",
    "log_evidence_is",
    "normalize_log_weights",
    "pareto_k",
    "systematic_resample",
    "weighted_quantiles",
    "SCALED",
    "Identifiability",
    "format_identifiability",
    "identify",
    "DEFAULT_DRAWS",
    "batch_function",
    "chunks",
    "draw_prior",
    "importance_sample",
    "map_evaluate",
    "reduce_importance",
    "QUANTILE_LEVELS",
    "Posterior",
    "TABLE2_BOUNDS",
    "Prior",
    "NOISE_MODELS",
    "Evaluation",
    "Problem",
    "ProblemEvaluator",
    "evaluate",
    "gaussian_loglik",
    "marginal_gaussian_loglik",
    "n_sim_frames",
    "gaussian_measurement_loglik",
    "validate_measurements",
    "validate_observation",
    "compare",
    "flow_contact_table",
    "plot_marginals",
    "plot_predictive",
    "predictive_bands",
    "RUN_GAP",
    "pool_runs",
    "run_seeds",
    "dt_mesh_configs",
    "ensemble_size_study",
    "numerics_study",
    "write_table",
    "DEFAULT_PARTICLES",
    "SMCSampler",
    "next_temperature",
    "smc",
    "Twin",
    "make_twin",
]
