"""Concealed-effect benchmark: GAW data sets with a hidden physical or camera effect.

The generator is deliberately separate from the fitting code (it imports nothing from
``vfcore.diagnose``) and uses *richer* mechanisms than the fitted extensions of
``vfcore/diagnose/extensions.py`` (see ``benchmarks/concealed/README.md`` for the mechanisms,
their ranges and sources). Each case is one observation of ``N_OBS`` frames:

    truth (E_body, E_cover, p_sub ~ U(Table 2 prior), rest at TABLE3)
    -> base simulation (SimConfig(mesh="coarse", dt=1e-4))
    -> effect (one of EFFECTS, or none for "control")
    -> N(0, sigma^2) noise, sigma ~ U[0.3, 1.0] mm^2
    -> kept when the recording phonates and the effect is *present*: the best base-model fit of
       the clean waveform leaves >= PRESENCE_SIGMA * sigma (:func:`unabsorbed_rms`); else redrawn

Output of :func:`write_suite` / the CLI::

    python -m benchmarks.concealed.generate --out DIR --seed S

- ``cases.json`` PUBLIC: fps, frame count, CSV name per case id (and the base model set-up),
  nothing about the effect;
- ``case_XX.csv`` PUBLIC: one column ``area_mm2``;
- ``truth.json`` HIDDEN: per id the effect label and parameters, material truth, noise sigma,
  the sub-frame offset, the clean waveform and the clean control-at-same-truth waveform;
- ``truth.npz`` HIDDEN: the same arrays (``clean_XX``, ``base_XX``, ``noisy_XX``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vfcore import TABLE3, Params, SimConfig, simulate
from vfcore.measures import estimate_f0

from .absorb import AUDIT_SEARCH, MaterialSpace, audit_presence, certify_absorption, unabsorbed_rms
from .config import BASE_CONFIG, MATERIAL_SETS, N_OBS, N_Y, PRESENCE_SIGMA, SCALE_ANCHOR, TRUTH_BOUNDS
from .mechanisms import (
    PIXEL_MM,
    SUB_C,
    asymmetric_area,
    boxcar_average,
    epithelium_profile,
    forward_extensions_available,
    frame_times,
    gap_profile,
    hr_times,
    leak_area,
    quantise_scale,
    sample_hr,
    subglottal_modes,
    zipper_area,
)

__all__ = [
    "BASE_CONFIG",
    "N_OBS",
    "N_Y",
    "EFFECTS",
    "PHYSICAL",
    "CAMERA",
    "LABELS",
    "TRUTH_BOUNDS",
    "Case",
    "frame_times",
    "sample_hr",
    "hr_times",
    "boxcar_average",
    "leak_area",
    "gap_profile",
    "zipper_area",
    "asymmetric_area",
    "epithelium_profile",
    "subglottal_modes",
    "quantise_scale",
    "oscillates",
    "amplitude",
    "phonates",
    "MaterialSpace",
    "unabsorbed_rms",
    "PRESENCE_SIGMA",
    "AUDIT_SEARCH",
    "audit_presence",
    "certify_absorption",
    "forward_extensions_available",
    "draw_truth",
    "make_case",
    "generate_suite",
    "write_suite",
    "main",
]


#: Sub-frame start of the observation in the kept window, frames (uniform).
OFFSET_RANGE = (60.0, 140.0)
#: Noise standard deviation, mm^2 (uniform).
SIGMA_RANGE = (0.3, 1.0)
#: Oscillation criterion of a usable case.
MIN_PEAK_MM2 = 2.0
#: Phonation criterion of a usable recording: the clean waveform's robust peak-to-trough amplitude
#: (95th minus 5th percentile) must reach this many mm^2 AND ``MIN_AMPLITUDE_SIGMA`` noise standard
#: deviations, and the noisy recording must still show a periodic oscillation (finite
#: autocorrelation f0, >= 2 cycles). Without it, an epithelium draw can keep a glottis
#: open at ~8.5 mm^2 with a 0.9 mm^2 ripple, and its noisy recording (sigma 0.31) has no f0.
MIN_AMPLITUDE_MM2 = 2.0
MIN_AMPLITUDE_SIGMA = 4.0
#: Detectability floor: an effect draw whose clean waveform differs from the control at the same
#: truth by less than this RMS (mm^2) is redrawn. Exposure has none: at 2000 fps its low-pass is
#: intrinsically weak on a 60-200 Hz GAW (README), so its cases are near-null by construction.
MIN_EFFECT_RMS = {"default": 0.5, "control": 0.0, "exposure": 0.0}
#: Draws tried for a present effect before the case is kept as *not present* (the draw with the
#: largest ``unabsorbed / sigma``); exposure at 2000 fps never passes (README).
PRESENCE_ATTEMPTS = 12
#: The presence rule's absorbing search in the five-parameter box: a denser design and longer
#: polishes than the three-parameter defaults, since a Nelder-Mead simplex in 5-D needs more steps.
FULL_PRESENCE_SEARCH = {"n_sobol": 128, "n_starts": 2, "maxfev": 150}

PHYSICAL = ("leak", "sep_ratio", "epithelium", "zipper", "subglottal", "asymmetry")
CAMERA = ("exposure", "frame_rate", "scale")
EFFECTS = PHYSICAL + CAMERA
#: Effects no catalogue entry models (the right answer is to name nothing): a slow amplitude
#: modulation (vocal tremor, 3-7 Hz), alternate cycles of different amplitude (diplophonia, a
#: period-doubled vibration), and a nonlinear area read-out (``A_ref (A/A_ref)^gamma``, an
#: edge-detection threshold that grows or shrinks the opening with its size).
OUTSIDE = ("tremor", "diplophonia", "gamma")
#: Two concealed effects in one recording: a forward-level effect re-simulated, then an
#: observation-level one applied to its waveform. Named right when either is named.
PAIRS = ("sep_ratio+leak", "epithelium+scale", "subglottal+zipper", "sep_ratio+frame_rate")
FORWARD = ("sep_ratio", "epithelium", "subglottal")
LABELS = EFFECTS + ("control",) + OUTSIDE + PAIRS
#: Cases per label in the default suite of the "three" material set (physical and camera effects
#: twice, 4 controls) and of the "full" set (each effect once, the effects outside the catalogue,
#: the pairs, 4 controls).
SUITE_COUNTS = {**{e: 2 for e in EFFECTS}, "control": 4}
SUITE_COUNTS_FULL = {**{e: 1 for e in EFFECTS + OUTSIDE + PAIRS}, "control": 4}

# ------------------------------------------------------------------ effect ranges (README)
LEAK_AREA_MM2 = (0.5, 3.0)  # total posterior chink area
LEAK_START_FRAC = (0.4, 0.75)  # chink runs from y = frac*L to the posterior end y = L
SEP_RATIO_RANGES = ((1.05, 1.2), (1.45, 1.6))
EPI_E_KPA = (8.0, 30.0)
EPI_H_MM = (0.03, 0.08)
EPI_MEDIAL_RATIO = (2.0, 4.0)  # medial / inferior-superior stiffness multiplier
EPI_MEDIAL_WIDTH_MM = (0.8, 1.5)  # Gaussian half-width (arc length) of the medial thickening
ZIP_LAG_CYCLES = (0.1, 0.3)
ZIP_POWER = (1.5, 3.0)
ZIP_ENV_Q = (0.5, 1.5)
SUB_TUBE_M = (0.15, 0.25)
SUB_Z1 = (0.5e6, 2.0e6)  # Pa s/m^3, first-mode peak impedance
SUB_ZETA1 = (0.08, 0.15)
ASYM_Q_RANGES = ((0.6, 0.8), (1.25, 1.5))
ASYM_LAG_CYCLES = (0.05, 0.2)
#: Per-layer spread of the right/left stiffness ratio: the cover and ligament ratios are Q times a
#: factor from this range (the body's is Q), so the right fold differs in *layer balance*, not
#: only in overall stiffness; the fitted lr_stiffness extension scales all three by one ratio.
ASYM_LAYER_SPREAD = (0.85, 1.15)
EXPOSURE_FRAC = (0.6, 1.0)
EXPOSURE_JITTER = (0.02, 0.05)  # relative sd of the per-frame exposure time
RATE_RANGES = ((0.93, 0.97), (1.03, 1.07))
SCALE_RANGES = ((0.8, 0.9), (1.1, 1.2))
LEAK_SHAPE_POWER = (0.5, 2.0)  # gap profile exponent along the chink (1: linear wedge)
TREMOR_HZ = (3.0, 7.0)
TREMOR_DEPTH = (0.15, 0.3)
DIPLO_DEPTH = (0.15, 0.3)
GAMMA_RANGES = ((0.6, 0.8), (1.3, 1.6))


def _uniform(rng, lo_hi) -> float:
    return float(rng.uniform(*lo_hi))


def _two_sided(rng, ranges) -> float:
    return _uniform(rng, ranges[int(rng.integers(len(ranges)))])


# ------------------------------------------------------------------ cases
def oscillates(gaw, fps: float) -> bool:
    g = np.asarray(gaw, dtype=float)
    return bool(g.size > 0 and np.all(np.isfinite(g)) and g.max() > MIN_PEAK_MM2 and math.isfinite(estimate_f0(g, fps)))


def amplitude(gaw) -> float:
    """Robust peak-to-trough amplitude (mm^2): 95th minus 5th percentile of the waveform."""
    g = np.asarray(gaw, dtype=float)
    return float(np.percentile(g, 95) - np.percentile(g, 5))


def phonates(clean, noisy, sigma: float, fps: float) -> bool:
    """Whether a case's recording is usable: the clean waveform oscillates with an amplitude of at
    least ``MIN_AMPLITUDE_MM2`` and ``MIN_AMPLITUDE_SIGMA * sigma``, and the noisy recording shows
    a periodic oscillation over at least two cycles (what a fit's input validation requires)."""
    if not oscillates(clean, fps):
        return False
    amp = amplitude(clean)
    if amp < MIN_AMPLITUDE_MM2 or amp < MIN_AMPLITUDE_SIGMA * sigma:
        return False
    y = np.asarray(noisy, dtype=float)
    if not np.all(np.isfinite(y)):
        return False
    f0 = estimate_f0(y, fps)
    return bool(math.isfinite(f0) and f0 > 0 and y.size * f0 / fps >= 2.0)


def _ok(res) -> bool:
    return bool(res.ok and oscillates(res.gaw, res.fps))


def draw_truth(rng, material: str = "three") -> Params:
    """The material truth: the parameters of ``MATERIAL_SETS[material]`` uniform in their bounds,
    the rest at TABLE3 (with "full", rho at ``SCALE_ANCHOR``)."""
    d = TABLE3.as_dict()
    if material == "full":
        d.update(SCALE_ANCHOR)
    for k, b in MATERIAL_SETS[material].items():
        d[k] = _uniform(rng, b)
    return Params(**d)


def _forward(label: str, truth: Params, rng, config: SimConfig, sim):
    """A forward-level effect's simulation and its parameters; ``None`` when it does not oscillate."""
    if not forward_extensions_available().get(label, True):
        raise NotImplementedError(f"SimConfig has no {label} fields in this vfcore")
    if label == "sep_ratio":
        r = _two_sided(rng, SEP_RATIO_RANGES)
        res = sim(truth, config.replace(sep_ratio=r))
        eff = {"sep_ratio": r}
    elif label == "epithelium":
        E = _uniform(rng, EPI_E_KPA)
        h = _uniform(rng, EPI_H_MM)
        mr = _uniform(rng, EPI_MEDIAL_RATIO)
        wd = _uniform(rng, EPI_MEDIAL_WIDTH_MM)
        prof = epithelium_profile(mr, wd, config.mesh)
        res = sim(truth, config.replace(epithelium_E_kpa=E, epithelium_h_mm=h, epithelium_profile=prof))
        eff = {
            "epithelium_E_kpa": E,
            "epithelium_h_mm": h,
            "medial_ratio": mr,
            "medial_width_mm": wd,
            "epithelium_profile": list(prof),
        }
    elif label == "subglottal":
        tube = _uniform(rng, SUB_TUBE_M)
        z1 = _uniform(rng, SUB_Z1)
        zeta = _uniform(rng, SUB_ZETA1)
        modes = subglottal_modes(tube, z1, zeta)
        res = sim(truth, config.replace(subglottal_modes=modes))
        eff = {
            "tube_length_m": tube,
            "c_m_s": SUB_C,
            "Z1_pa_s_m3": z1,
            "zeta1": zeta,
            "subglottal_modes": [list(m) for m in modes],
        }
    else:
        raise ValueError(f"{label!r} is not a forward-level effect; known: {FORWARD}")
    if not _ok(res) or res.cycles is None:
        return None
    return res, eff


def _cycle_index(res, t: np.ndarray) -> np.ndarray:
    """Index of the simulated cycle (minimum to minimum) each time of ``t`` falls in."""
    return np.searchsorted(np.asarray(res.cycles.t_start, dtype=float), t, side="right")


@dataclass
class Case:
    id: str
    label: str
    effect: dict
    truth: dict
    offset_frames: float
    sigma: float
    fps: float
    clean: np.ndarray
    base: np.ndarray  # clean control-at-same-truth (same offset, no effect)
    gaw: np.ndarray  # clean + noise: the public observation
    attempts: int = 1
    notes: list = field(default_factory=list)
    unabsorbed: float = math.nan  # unabsorbed_rms of the clean waveform (mm^2); nan for controls
    absorbing_fit: dict = field(default_factory=dict)

    @property
    def present(self) -> bool:
        """The effect survives the best base-model fit by >= PRESENCE_SIGMA noise sd (controls: False)."""
        return bool(self.label != "control" and self.unabsorbed >= PRESENCE_SIGMA * self.sigma)

    @property
    def effect_rms(self) -> float:
        return float(np.sqrt(np.mean((self.clean - self.base) ** 2)))

    @property
    def effect_loglik(self) -> float:
        """``sum (clean - base)^2 / (2 sigma^2)``: log-likelihood gap between the effect and the
        base model at the truth (an upper bound on what a fit could gain; the base fit absorbs part)."""
        return float(np.sum((self.clean - self.base) ** 2) / (2.0 * self.sigma**2))


def apply_effect(
    label: str,
    base,
    truth: Params,
    offset: float,
    rng,
    config: SimConfig = BASE_CONFIG,
    n_obs: int = N_OBS,
    sim=simulate,
    shapes: bool = True,
):
    """Draw the effect parameters and return ``(clean, effect_params)``; ``None`` when the
    effect's simulation does not oscillate (caller redraws). ``shapes``: draw the shape knobs
    that the suites of the "three" set held fixed (the leak's gap profile)."""
    fps = config.fps
    t_hr = hr_times(base)
    t = frame_times(n_obs, offset, fps)
    gaw_hr = np.asarray(base.gaw_hr, dtype=float)
    L = config.length_mm
    if label == "control":
        return sample_hr(gaw_hr, t_hr, t), {}
    if label == "leak":
        area = _uniform(rng, LEAK_AREA_MM2)
        start = _uniform(rng, LEAK_START_FRAC)
        power = _uniform(rng, LEAK_SHAPE_POWER) if shapes else 1.0
        g = gap_profile(area, start, L, power=power)
        w = sample_hr(gaw_hr / L, t_hr, t)
        return leak_area(w, g, length_mm=L), {
            "chink_area_mm2": area,
            "start_frac": start,
            "shape_power": power,
            "posterior_gap_mm": float(g.max()),
            "n_y": N_Y,
            "env": "uniform",
        }
    if label == "zipper":
        lag = _uniform(rng, ZIP_LAG_CYCLES)
        pw = _uniform(rng, ZIP_POWER)
        q = _uniform(rng, ZIP_ENV_Q)
        clean = zipper_area(gaw_hr / L, t_hr, t, lag / base.f0, pw, q, L)
        return clean, {
            "lag_cycles": lag,
            "lag_s": lag / base.f0,
            "power": pw,
            "env_q": q,
            "n_y": N_Y,
            "env_normalised": True,
        }
    if label == "exposure":
        e = _uniform(rng, EXPOSURE_FRAC)
        j = _uniform(rng, EXPOSURE_JITTER)
        ek = np.clip(e * (1.0 + j * rng.standard_normal(n_obs)), 0.05, 1.0)
        return boxcar_average(gaw_hr, t_hr, t, ek / fps), {"exposure_fraction": e, "jitter_rel_sd": j}
    if label == "frame_rate":
        r = _two_sided(rng, RATE_RANGES)
        return sample_hr(gaw_hr, t_hr, frame_times(n_obs, offset, fps, r)), {"rate_ratio": r}
    if label == "scale":
        s = _two_sided(rng, SCALE_RANGES)
        return quantise_scale(sample_hr(gaw_hr, t_hr, t), s, L), {"scale": s, "pixel_mm": PIXEL_MM}
    if label in FORWARD:
        out = _forward(label, truth, rng, config, sim)
        if out is None:
            return None
        res, eff = out
        return sample_hr(np.asarray(res.gaw_hr), hr_times(res), t), eff
    if "+" in label:
        first, second = label.split("+")
        out = _forward(first, truth, rng, config, sim)
        if out is None or not math.isfinite(out[0].f0):
            return None
        res, eff1 = out
        got = apply_effect(second, res, truth, offset, rng, config, n_obs, sim, shapes)
        if got is None:
            return None
        return got[0], {first: eff1, second: got[1]}
    if label == "tremor":
        f_m, depth, phase = _uniform(rng, TREMOR_HZ), _uniform(rng, TREMOR_DEPTH), _uniform(rng, (0.0, 2 * math.pi))
        a = sample_hr(gaw_hr, t_hr, t)
        return a * (1.0 + depth * np.sin(2 * math.pi * f_m * t + phase)), {
            "mod_hz": f_m,
            "depth": depth,
            "phase_rad": phase,
        }
    if label == "diplophonia":
        depth = _uniform(rng, DIPLO_DEPTH)
        a = sample_hr(gaw_hr, t_hr, t)
        # cycles start at an area minimum, so the step between alternate gains falls where the area is least
        sign = np.where(_cycle_index(base, t) % 2 == 0, 1.0, -1.0)
        return a * (1.0 + depth * sign), {"depth": depth}
    if label == "gamma":
        g = _two_sided(rng, GAMMA_RANGES)
        a = np.clip(sample_hr(gaw_hr, t_hr, t), 0.0, None)
        ref = float(np.percentile(a, 95))
        return ref * (a / ref) ** g, {"gamma": g, "ref_mm2": ref}
    if label == "asymmetry":
        Q = _two_sided(rng, ASYM_Q_RANGES)
        lag = _uniform(rng, ASYM_LAG_CYCLES)
        q_layer = {
            "E_body": Q,
            "E_cover": Q * _uniform(rng, ASYM_LAYER_SPREAD),
            "E_lig": Q * _uniform(rng, ASYM_LAYER_SPREAD),
        }
        d = truth.as_dict()
        for k, qk in q_layer.items():
            d[k] *= qk
        right = sim(Params(**d), config)
        if not _ok(right) or right.cycles is None or not math.isfinite(right.f0):
            return None
        t_c = (offset + n_obs / 2) / fps
        try:
            clean = asymmetric_area(base, right, t, lag, t_c)
        except ValueError:
            return None
        return clean, {
            "Q": Q,
            "Q_layers": q_layer,
            "lag_cycles": lag,
            "f0_left_hz": base.f0,
            "f0_right_hz": right.f0,
            "right_params": d,
        }
    raise ValueError(f"unknown label {label!r}; known: {LABELS}")


def make_case(
    case_id: str,
    label: str,
    seed_seq: np.random.SeedSequence,
    config: SimConfig = BASE_CONFIG,
    n_obs: int = N_OBS,
    max_attempts: int = 20,
    sim=simulate,
    presence: bool = True,
    presence_attempts: int = PRESENCE_ATTEMPTS,
    material: str = "three",
) -> Case:
    """One case, deterministic in ``seed_seq``: draw truth until the base oscillates, draw the
    offset and the effect (redrawn when its simulation does not oscillate), add noise; the whole
    draw is repeated (same stream) when the recording does not phonate (:func:`phonates`) and,
    with ``presence``, when the effect is not present (:data:`PRESENCE_SIGMA`, at most
    ``presence_attempts`` such draws; then the draw with the largest ``unabsorbed / sigma`` is
    kept and its ``present`` is False). ``material``: the material set of the truth and of the
    presence rule's absorbing fit (:data:`.config.MATERIAL_SETS`)."""
    rng = np.random.default_rng(seed_seq)
    full = material == "full"
    best_absent, n_absent = None, 0
    for attempt in range(1, max_attempts + 1):
        truth = draw_truth(rng, material)
        base = sim(truth, config)
        if not _ok(base) or base.cycles is None or not math.isfinite(base.f0):
            continue
        offset = _uniform(rng, OFFSET_RANGE)
        base_clean = sample_hr(np.asarray(base.gaw_hr), hr_times(base), frame_times(n_obs, offset, config.fps))
        floor = MIN_EFFECT_RMS.get(label, MIN_EFFECT_RMS["default"])
        out = None
        for _ in range(3):
            out = apply_effect(label, base, truth, offset, rng, config, n_obs, sim, shapes=full)
            if (
                out is not None
                and oscillates(out[0], config.fps)
                and np.sqrt(np.mean((out[0] - base_clean) ** 2)) >= floor
            ):
                break
            out = None
        if out is None:
            continue
        clean, eff = out
        sigma = _uniform(rng, SIGMA_RANGE)
        noisy = clean + sigma * rng.standard_normal(n_obs)
        if not phonates(clean, noisy, sigma, config.fps):
            # not a usable recording (no phonation, or an oscillation lost in the noise): redraw
            # from the same stream; a case that passes consumes exactly the draws it did before
            continue
        case = Case(
            case_id, label, eff, truth.as_dict(), offset, sigma, config.fps, clean, base_clean, noisy, attempts=attempt
        )
        if not presence or label == "control":
            return case
        case.unabsorbed, case.absorbing_fit = unabsorbed_rms(
            clean, truth, config, bounds=MATERIAL_SETS[material], **(FULL_PRESENCE_SEARCH if full else {})
        )
        if case.present:
            return case
        n_absent += 1
        if best_absent is None or case.unabsorbed / case.sigma > best_absent.unabsorbed / best_absent.sigma:
            best_absent = case
        if n_absent >= presence_attempts:
            best_absent.notes.append(
                f"not present: no draw in {n_absent} left >= {PRESENCE_SIGMA:.2f} sigma unabsorbed by the base model"
            )
            return best_absent
    if best_absent is not None:
        best_absent.notes.append("not present (attempts exhausted)")
        return best_absent
    raise RuntimeError(f"case {case_id} ({label}): no oscillating draw in {max_attempts} attempts")


def suite_labels(counts: dict | None = None) -> list[str]:
    counts = dict(SUITE_COUNTS if counts is None else counts)
    avail = forward_extensions_available()
    for k, ok in avail.items():
        if not ok and counts.get(k):
            print(
                f"[concealed] skipping {k!r}: SimConfig lacks its fields (forward-model work not present)",
                file=sys.stderr,
            )
            counts[k] = 0
    return [lab for lab in LABELS for _ in range(counts.get(lab, 0))]


def _make_case_star(args):
    return make_case(*args[:5], sim=args[5], presence=args[6], material=args[7])


def generate_suite(
    seed: int,
    counts: dict | None = None,
    config: SimConfig = BASE_CONFIG,
    n_obs: int = N_OBS,
    sim=simulate,
    presence: bool = True,
    workers: int = 1,
    material: str = "three",
) -> list[Case]:
    """The benchmark suite: each label ``counts[label]`` times (default :data:`SUITE_COUNTS`),
    in an order shuffled by ``seed`` (ids carry no label information). Case i uses the i-th
    child of ``SeedSequence(seed)`` (the last child shuffles the order). ``workers`` > 1 makes
    the cases in a process pool (same cases: each depends on its own seed only)."""
    if counts is None and material == "full":
        counts = SUITE_COUNTS_FULL
    labels = suite_labels(counts)
    children = np.random.SeedSequence(seed).spawn(len(labels) + 1)
    order = np.random.default_rng(children[-1]).permutation(len(labels))
    jobs = [(f"{i:02d}", labels[j], children[i], config, n_obs, sim, presence, material) for i, j in enumerate(order)]
    if workers > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(workers) as ex:
            return list(ex.map(_make_case_star, jobs))
    return [_make_case_star(j) for j in jobs]


# ------------------------------------------------------------------ output
def public_fixed(material: str = "three") -> dict:
    """The parameters a suite holds fixed (Table 3 values, the anchor of the "full" set), all but
    the drawn ones, as written to the public ``cases.json``."""
    d = {**TABLE3.as_dict(), **(SCALE_ANCHOR if material == "full" else {})}
    return {k: v for k, v in d.items() if k not in MATERIAL_SETS[material]}


def write_suite(
    cases: list[Case],
    out: str | os.PathLike,
    seed: int | None = None,
    config: SimConfig = BASE_CONFIG,
    material: str = "three",
) -> None:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    public = {
        "description": "GAW observations (mm^2) for model diagnosis; fit the base model to each case",
        "model": {"mesh": config.mesh, "dt": config.dt, "duration": config.duration, "discard": config.discard},
        "material": material,
        "estimated": list(MATERIAL_SETS[material]),
        "fixed": public_fixed(material),
        "cases": [{"id": c.id, "file": f"case_{c.id}.csv", "fps": c.fps, "n_frames": int(c.gaw.size)} for c in cases],
    }
    (out / "cases.json").write_text(json.dumps(public, indent=1))
    for c in cases:
        np.savetxt(out / f"case_{c.id}.csv", c.gaw, fmt="%.6f", header="area_mm2", comments="")
    hidden = {
        "seed": seed,
        "n_obs": int(cases[0].gaw.size) if cases else 0,
        "cases": {
            c.id: {
                "label": c.label,
                "effect": c.effect,
                "truth": c.truth,
                "offset_frames": c.offset_frames,
                "sigma_mm2": c.sigma,
                "effect_rms_mm2": c.effect_rms,
                "effect_loglik": c.effect_loglik,
                "attempts": c.attempts,
                "unabsorbed_rms_mm2": c.unabsorbed,
                "present": c.present,
                "absorbing_fit": c.absorbing_fit,
                "notes": c.notes,
                "clean": c.clean.tolist(),
                "base_clean": c.base.tolist(),
            }
            for c in cases
        },
    }
    (out / "truth.json").write_text(json.dumps(hidden, indent=1, default=float))
    arrays = {}
    for c in cases:
        arrays[f"clean_{c.id}"] = c.clean
        arrays[f"base_{c.id}"] = c.base
        arrays[f"noisy_{c.id}"] = c.gaw
    np.savez(out / "truth.npz", **arrays)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="directory of the suite to write")
    ap.add_argument(
        "--audit",
        metavar="SUITE",
        help="re-test an existing suite's presence rule with a stronger absorption search "
        "(writes SUITE/audit.json; the recordings are unchanged)",
    )
    ap.add_argument(
        "--audit-method",
        choices=("both", "continuation", "design"),
        default="both",
        help="absorption search of --audit: window continuation, a dense design, or both "
        "(default; the design only where the continuation left the effect present)",
    )
    ap.add_argument(
        "--certify",
        metavar="SUITE",
        help="after a diagnosis of SUITE: polish the base model from each report's base posterior "
        "(--reports) and mark the effects it absorbs (writes REPORTS/absorption.json)",
    )
    ap.add_argument("--reports", metavar="DIR", help="the diagnosis reports of --certify (case_XX.json)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1, help="processes (same cases for any number)")
    ap.add_argument(
        "--material",
        choices=tuple(MATERIAL_SETS),
        default="full",
        help="material truth: 'full' draws every combination a GAW determines (the common scale at "
        "the anchor) and adds effects outside the catalogue and two-effect cases; 'three' "
        "draws E_body, E_cover, p_sub with the rest at Table 3 (the suites of seeds 0-9)",
    )
    ap.add_argument(
        "--no-presence",
        action="store_true",
        help="skip the presence rule (effects may then be absorbed by the base model)",
    )
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    if a.audit:
        doc = audit_presence(a.audit, workers=a.workers, method=a.audit_method)
        print(f"audit of {a.audit} in {time.perf_counter() - t0:.1f} s ({doc['method']}, search {doc['search']})")
        old = json.loads((Path(a.audit) / "truth.json").read_text())["cases"]
        for cid, r in doc["cases"].items():
            if old[cid]["label"] == "control":
                continue
            s_ = r["sigma_mm2"]
            print(
                f"  {cid} {old[cid]['label']:11s} unabsorbed {r['generated_unabsorbed_rms_mm2'] / s_:5.2f} -> "
                f"{r['unabsorbed_rms_mm2'] / s_:5.2f} sigma  {'present' if r['present'] else 'NOT PRESENT'}"
                + ("  (changed)" if r["present"] != old[cid]["present"] else "")
            )
        return 0
    if a.certify:
        if not a.reports:
            ap.error("--certify needs --reports DIR (the diagnosis reports)")
        if not (Path(a.certify) / "truth.json").exists():
            ap.error(f"--certify: no truth.json in {a.certify}")
        if not Path(a.reports).is_dir():
            ap.error(f"--reports: {a.reports} is not a directory")
        doc = certify_absorption(a.certify, a.reports, workers=a.workers)
        print(
            f"absorption from the reports' base fits in {time.perf_counter() - t0:.1f} s "
            f"({len(doc['cases'])} effect cases, Nelder-Mead {doc['maxfev']} simulations each)"
        )
        for cid, r in doc["cases"].items():
            print(
                f"  {cid} unabsorbed {r['unabsorbed_rms_mm2'] / r['sigma_mm2']:5.2f} sigma  "
                + ("ABSORBED" if r["absorbed"] else "not shown absorbed")
            )
        return 0
    if not a.out:
        ap.error("--out is required (or --audit SUITE, or --certify SUITE)")
    cases = generate_suite(a.seed, presence=not a.no_presence, workers=a.workers, material=a.material)
    write_suite(cases, a.out, a.seed, material=a.material)
    dt = time.perf_counter() - t0
    counts: dict[str, int] = {}
    for c in cases:
        counts[c.label] = counts.get(c.label, 0) + 1
    print(f"{len(cases)} cases in {dt:.1f} s -> {a.out}")
    print("labels:", counts)
    for c in sorted(cases, key=lambda c: c.label):
        print(
            f"  {c.id} {c.label:11s} effect RMS {c.effect_rms:6.2f} mm^2  sigma {c.sigma:.2f}  "
            f"loglik gap {c.effect_loglik:8.1f}  peak {c.clean.max():5.1f}  attempts {c.attempts}  "
            f"unabsorbed {c.unabsorbed:5.2f} mm^2 ({c.unabsorbed / c.sigma:4.2f} sigma)"
            + ("" if c.label in ("control",) + OUTSIDE else ("  present" if c.present else "  NOT PRESENT"))
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
