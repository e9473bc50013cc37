"""The recording and model settings of ``vfinfer diagnose`` and of the concealed-effect benchmark
(:ref:`validation-diagnose`): the simulated window and the parameters the base model estimates.

The diagnosis' own settings (particles, continuation, material first, ...) are
:class:`vfcore.diagnose.options.DiagnoseOptions`, the one source of their defaults for the library,
the command line, the service and the benchmark.
"""

from __future__ import annotations

#: simulated time and discarded transient, s (the paper's 0.55 s; the suites' window)
DURATION_S = 0.55
DISCARD_S = 0.25
#: the base model estimates every combination of the six scaled parameters a GAW determines; rho,
#: the best known of them in tissue, anchors the common scale (:ref:`diagnose-naming-material-first`)
DEFAULT_ESTIMATE = "E_body,E_cover,E_lig,p_sub,eta"
