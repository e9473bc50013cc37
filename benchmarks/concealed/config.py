"""Set-up shared by the concealed-effect generator and its absorption searches.

The forward-model settings of every case, the observation length, the material box the truth is
drawn from (and the base model may move in when it tries to absorb an effect), and the presence
threshold. Nothing here depends on the fitting code (``vfcore.diagnose``).
"""

from __future__ import annotations

import math

from vfcore import SimConfig

__all__ = [
    "BASE_CONFIG",
    "N_OBS",
    "N_Y",
    "TRUTH_BOUNDS",
    "FULL_BOUNDS",
    "MATERIAL_SETS",
    "SCALE_ANCHOR",
    "PRESENCE_SIGMA",
]

#: Forward-model settings of every case (the fit is expected to use the same).
BASE_CONFIG = SimConfig(mesh="coarse", dt=1e-4)
#: Frames per observation.
N_OBS = 400
#: Slices along the fold length for the 3D-like effects (leak, zipper).
N_Y = 20
#: Material truth drawn uniformly in the default prior (vfcore.inference.prior.TABLE2_BOUNDS);
#: the other parameters are at TABLE3. Copied here so the generator does not depend on the
#: inference package (values: Hadwin et al. 2019, Table 2).
TRUTH_BOUNDS = {"E_body": (9.0, 15.0), "E_cover": (250.0, 950.0), "p_sub": (400.0, 1800.0)}
#: The material truth of a recording whose every parameter is unknown: the five scale-invariant
#: combinations of the six scaled parameters drawn from Table 2, the common scale fixed by
#: ``SCALE_ANCHOR``. The glottal area waveform is exactly unchanged when E_body, E_cover, E_lig,
#: p_sub, rho and eta are multiplied by one factor (:ref:`inference-scale-the-common-scale-what-a`), so a
#: truth drawn with rho elsewhere in Table 2's [950, 1200] kg/m^3 is the same recording as its
#: rescaled copy with rho at the anchor; drawing the other five at the anchor keeps them in the box.
FULL_BOUNDS = {
    "E_body": (9.0, 15.0),
    "E_cover": (250.0, 950.0),
    "E_lig": (0.5, 3.0),
    "p_sub": (400.0, 1800.0),
    "eta": (1.0, 7.0),
}
#: The scale anchor the diagnosis assumes for a full-material suite: rho at Table 3 (kg/m^3).
SCALE_ANCHOR = {"rho": 1051.0}
#: Material sets of a suite (``generate.py --material``): "three" draws E_body, E_cover and p_sub
#: with the rest at Table 3 (the suites of seeds 0-9), "full" every combination a GAW determines.
MATERIAL_SETS = {"three": TRUTH_BOUNDS, "full": FULL_BOUNDS}
#: Presence rule: an effect counts as *present* in a case only when the best base-model
#: fit of its clean waveform (material parameters free in TRUTH_BOUNDS, any sub-frame lag; see
#: :func:`unabsorbed_rms`) leaves an RMS of at least ``PRESENCE_SIGMA * sigma``. The factor is the
#: smallest for which the benchmark's effect-size criterion (30 %) can be met at all: if the base absorbs all
#: but ``e`` of the effect and an extension removes the rest, the residual RMS falls from
#: ``sqrt(sigma^2 + e^2)`` to ``sigma``, a 30 % gain exactly when ``e = sigma * sqrt(1/0.7^2 - 1)``.
#: Below it the effect is absorbed by the material parameters to within the noise (seed-0 scale
#: and frame-rate cases drawn without the rule: base residual 0.52-0.74 mm^2 against sigma 0.52-0.69).
PRESENCE_SIGMA = math.sqrt(1.0 / 0.7**2 - 1.0)
