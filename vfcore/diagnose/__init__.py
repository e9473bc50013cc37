"""Find the missing physics: locate a fit/recording mismatch on the glottal cycle, a catalogue of
optional model extensions, and an evidence-based ranking; :func:`diagnose` runs the whole diagnosis
with the settings of a :class:`DiagnoseOptions`. See :ref:`diagnose`."""

from .extensions import CATALOGUE, Extension, ExtParam, get, implemented, matching
from .locate import (
    DEFAULT_MEASURES,
    PHASES,
    SPREAD,
    LocateReport,
    MeasureCheck,
    from_posterior,
    locate,
    measure_pvalues,
    noise_sd,
    phase_labels,
    predictive_measures,
)
from .options import DiagnoseOptions
from .pipeline import diagnose
from .rank import NO_FINDING, CandidateRow, RankReport, compare_fits, rank_extensions, residual_removed
from .report import DiagnoseReport

__all__ = [
    "diagnose",
    "DiagnoseOptions",
    "DiagnoseReport",
    "CATALOGUE",
    "Extension",
    "ExtParam",
    "get",
    "implemented",
    "matching",
    "DEFAULT_MEASURES",
    "PHASES",
    "SPREAD",
    "LocateReport",
    "MeasureCheck",
    "from_posterior",
    "locate",
    "measure_pvalues",
    "noise_sd",
    "phase_labels",
    "predictive_measures",
    "NO_FINDING",
    "CandidateRow",
    "RankReport",
    "compare_fits",
    "rank_extensions",
    "residual_removed",
]
