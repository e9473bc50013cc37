"""What the data determine and what the prior does: the identifiability table of a fitted posterior.

The model has an exact symmetry (:ref:`inference-scale-the-common-scale-what-a`):
multiplying E_body, E_cover, E_lig, p_sub, rho and eta by one factor ``c`` (x0 unchanged) leaves the
glottal area waveform unchanged, while contact pressures scale by ``c`` and the flow rate by ``sqrt(c)``.
Every quantity of the fold's equations carries one power of mass (stiffness, load, mass, damping) and
the air density enters the flow velocity only, so ``c`` is a change of the unit of mass that lengths
and times do not see. A GAW therefore determines at most the scale-invariant combinations (any
monomial ``prod theta_i^a_i`` with ``sum a_i = 0``, e.g. ``E_cover / p_sub``, ``eta^2 / (rho p_sub)``);
the common scale is set by the prior's box unless something anchors it: a fixed value of one of the
six, or a measurement (``Problem(measurements=...)``).

:func:`identify` reports, from a posterior and its prior:

(a) per parameter: posterior mean and sd, and sd / prior sd (uniform prior: sd = width / sqrt(12));
(b) in log coordinates of the free parameters: the principal directions of the posterior covariance
    (eigenvectors), the posterior sd along each and the prior's sd along the same direction (their
    ratio says how much the data narrowed it), least narrowed first;
(c) the common-scale direction (equal weights on the logs of the free scaled parameters, normalised):
    its posterior sd against the prior's sd along it and against the sd the prior box allows along
    the ray through the posterior mean (the conditional prior there, which is what the posterior
    reduces to where the likelihood is flat along the ray); the scale-invariant combinations with
    their posterior means and sds;
(d) plain warnings when the common scale is set by the prior's box.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..params import PARAM_UNITS, TABLE3, TO_SI
from .diagnostics import weighted_quantiles
from .identify_table import Identifiability, format_identifiability
from .prior import Prior

#: The parameters that scale together (x0 is geometric and does not).
SCALED: tuple[str, ...] = ("E_body", "E_cover", "E_lig", "p_sub", "rho", "eta")

#: Dimensions (kg, m, s) of the scaled parameters: every one carries one power of mass.
_DIMS = {
    "E_body": (1, -1, -2),
    "E_cover": (1, -1, -2),
    "E_lig": (1, -1, -2),
    "p_sub": (1, -1, -2),
    "rho": (1, -3, 0),
    "eta": (1, -1, -1),
}

#: The posterior sd along the common scale above this fraction of what the prior box allows there
#: means the box, not the data, sets the scale.
SCALE_RATIO_WARN = 0.5
#: Outer fraction of the ray (each end) and the posterior mass in it that counts as piling against the box.
EDGE_FRACTION = 0.05
EDGE_MASS_WARN = 0.25

ANCHOR_HINT = "anchor it (--measure p_sub=MEAN:SD, a density measurement --measure rho=MEAN:SD, or --fix)"


def uniform_log_moments(lo: float, hi: float) -> tuple[float, float]:
    """Mean and variance of ``log theta`` for ``theta ~ Uniform(lo, hi)``, ``0 <= lo < hi``.

    With ``t = theta / hi`` uniform on ``[r, 1]``, ``r = lo / hi``: ``E log t = (r - 1 - r log r) / (1 - r)``
    and ``E log^2 t = (2 - r (log^2 r - 2 log r + 2)) / (1 - r)`` (integrate ``log t`` and ``log^2 t``
    by parts). For ``1 - r < 1e-3`` the variance is taken as ``log(r)^2 / 12`` (log nearly linear
    there; the relative error is below 1e-6), which avoids the cancellation of the exact form."""
    lo, hi = float(lo), float(hi)
    if not (0.0 <= lo < hi and math.isfinite(hi)):
        raise ValueError(f"need 0 <= lo < hi, got ({lo}, {hi})")
    r = lo / hi
    lr = math.log(r) if r > 0 else 0.0
    if 1.0 - r < 1e-3:
        return math.log(hi) + 0.5 * lr, lr * lr / 12.0
    rl = r * lr if r > 0 else 0.0
    m1 = (r - 1.0 - rl) / (1.0 - r)
    m2 = (2.0 - (r * lr * lr - 2.0 * rl + 2.0 * r)) / (1.0 - r)
    return math.log(hi) + m1, max(m2 - m1 * m1, 0.0)


def _ray_sd(length: float, rate: float) -> float:
    """sd of ``s`` with density proportional to ``exp(rate s)`` on an interval of ``length``:
    ``var = 1/rate^2 - length^2 / (4 sinh^2(rate length / 2))`` (``length^2 / 12`` for small ``rate length``)."""
    if not math.isfinite(length):
        return math.inf
    x = rate * length
    if x < 1e-3:
        return length / math.sqrt(12.0)
    var = 1.0 / rate**2 - length**2 / (4.0 * math.sinh(0.5 * x) ** 2)
    return math.sqrt(max(var, 0.0))


def _ray_end_mass(rate: float, length: float, frac: float) -> tuple[float, float]:
    """Mass of the density ``exp(rate s)`` on ``[0, length]`` in its first and last ``frac`` of the length."""
    x = rate * length
    if not math.isfinite(x) or x < 1e-9:
        return frac, frac
    tot = math.expm1(x)
    return math.expm1(frac * x) / tot, (math.exp(x) - math.exp((1.0 - frac) * x)) / tot


def _unit(exponents: Mapping[str, float]) -> str:
    """SI unit of ``prod theta_i^a_i`` (mass cancels because ``sum a_i = 0``)."""
    m = sum(a * _DIMS[n][1] for n, a in exponents.items())
    s = sum(a * _DIMS[n][2] for n, a in exponents.items())

    def part(sym, e):
        e = int(round(abs(e)))
        return sym if e == 1 else f"{sym}^{e}"

    num = [part(sym, e) for sym, e in (("m", m), ("s", s)) if e > 0]
    den = [part(sym, e) for sym, e in (("m", m), ("s", s)) if e < 0]
    if not num and not den:
        return "1"
    return ("*".join(num) or "1") + ("/" + "/".join(den) if den else "")


def combination_label(exponents: Mapping[str, float]) -> str:
    def part(n, a):
        a = int(round(abs(a)))
        return n if a == 1 else f"{n}^{a}"

    num = [part(n, a) for n, a in exponents.items() if a > 0]
    den = [part(n, a) for n, a in exponents.items() if a < 0]
    top = "*".join(num)
    bottom = den[0] if len(den) == 1 else "(" + "*".join(den) + ")"
    return f"{top}/{bottom}"


def scale_invariant_combinations(free: tuple[str, ...]) -> list[dict[str, float]]:
    """Exponent maps ``{name: a}`` (``sum a = 0``) of the combinations a GAW can determine among the
    free scaled parameters ``free``: each one over p_sub (over the first free one when p_sub is not
    free), and the viscous length ``eta^2 / (rho p_sub)`` when all three are free."""
    free = tuple(n for n in SCALED if n in free)
    if len(free) < 2:
        return []
    ref = "p_sub" if "p_sub" in free else free[0]
    out = [{n: 1.0, ref: -1.0} for n in free if n != ref]
    if all(n in free for n in ("eta", "rho", "p_sub")):
        out.append({"eta": 2.0, "rho": -1.0, "p_sub": -1.0})
    return out


def _wmean_cov(X: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    m = w @ X
    d = X - m
    return m, (d * w[:, None]).T @ d


def identify(
    post, prior: Prior, measurements: Mapping[str, tuple[float, float]] | None = None, *, use: str = "weighted"
) -> Identifiability:
    """The identifiability table of ``post`` (a :class:`~vfcore.inference.posterior.Posterior`) fitted
    under ``prior``; ``measurements`` ``{name: (mean, sd)}`` are those of the problem (they anchor the
    common scale). ``use``: ``"weighted"`` (every draw with its weight) or ``"resampled"`` (the equally
    weighted resampled ensemble)."""
    names, X, w = _draws(post, prior, use)
    measurements = dict(measurements or {})
    parameters = _parameter_rows(names, X, w, prior)  # (a)
    lv = _LogView.of(names, X, w, prior)
    free = tuple(n for n in SCALED if n in lv.names)
    v_scale = None
    if len(free) >= 2:
        v_scale = np.array([1.0 / math.sqrt(len(free)) if n in free else 0.0 for n in lv.names])
    principal = _principal_directions(lv, v_scale)  # (b)
    anchors = _anchors(names, prior, measurements)
    scale = None
    combinations: list[dict] = []
    warnings: list[str] = []
    if v_scale is not None:
        scale, piled = _common_scale(lv, w, v_scale, free, names, prior, measurements)  # (c)
        if scale["set_by_prior"]:
            warnings.append(_scale_warning(scale, piled, anchors))  # (d)
        combinations = _combinations(lv, w, free)
    return Identifiability(
        parameters=parameters,
        principal=principal,
        scale=scale,
        combinations=combinations,
        anchors=anchors,
        warnings=warnings,
        log_names=list(lv.names),
    )


def _draws(post, prior: Prior, use: str) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """``(names, X (n, d), w (n,))``: the draws of positive weight and their weights, normalised."""
    names = tuple(post.names)
    if names != tuple(prior.names):
        raise ValueError(f"posterior parameters {names} differ from the prior's {prior.names}")
    if use == "weighted":
        X = np.atleast_2d(np.asarray(post.samples, dtype=float))
        w = np.asarray(post.weights, dtype=float)
    elif use == "resampled":
        X = np.atleast_2d(np.asarray(post.resampled_samples, dtype=float))
        w = np.full(X.shape[0], 1.0 / max(X.shape[0], 1))
    else:
        raise ValueError(f"use must be 'weighted' or 'resampled', got {use!r}")
    if X.shape != (w.size, len(names)):
        raise ValueError(f"samples of shape {X.shape} do not match {w.size} weights x {len(names)} parameters")
    keep = w > 0
    return names, X[keep], w[keep] / np.sum(w[keep])


def _parameter_rows(names, X: np.ndarray, w: np.ndarray, prior: Prior) -> list[dict]:
    """(a) Per parameter in paper units: posterior mean and sd, the uniform prior's sd and their ratio."""
    mean, cov = _wmean_cov(X, w)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    prior_sd = (prior.hi - prior.lo) / math.sqrt(12.0)
    return [
        {
            "name": n,
            "unit": PARAM_UNITS[n],
            "mean": float(mean[i]),
            "sd": float(sd[i]),
            "prior_sd": float(prior_sd[i]),
            "ratio": float(sd[i] / prior_sd[i]),
        }
        for i, n in enumerate(names)
    ]


@dataclass(frozen=True)
class _LogView:
    """The draws in log coordinates of the free parameters whose draws are all > 0."""

    cols: list[int]  # their columns in the parameter vector
    names: list[str]
    L: np.ndarray  # (n, len(cols)) log draws
    pvar: np.ndarray  # (len(cols),) prior variance of each log
    mean: np.ndarray
    cov: np.ndarray

    @classmethod
    def of(cls, names, X: np.ndarray, w: np.ndarray, prior: Prior) -> _LogView:
        cols = [i for i, n in enumerate(names) if np.all(X[:, i] > 0)]
        L = np.log(X[:, cols])
        lmom = [uniform_log_moments(prior.lo[i], prior.hi[i]) for i in cols]
        pvar = np.array([v for _, v in lmom])
        lmean, lcov = _wmean_cov(L, w)
        return cls(cols, [names[i] for i in cols], L, pvar, lmean, lcov)

    def prior_sd_along(self, v: np.ndarray) -> float:
        """The prior's sd of ``v @ log theta`` (the logs independent under the uniform box prior)."""
        return float(math.sqrt(float(np.sum(v * v * self.pvar))))


def _principal_directions(lv: _LogView, v_scale: np.ndarray | None) -> list[dict]:
    """(b) The eigenvectors of the log posterior covariance with posterior and prior sd along each (and
    their alignment with the common scale), least narrowed first."""
    evals, evecs = np.linalg.eigh(lv.cov) if len(lv.cols) else (np.empty(0), np.empty((0, 0)))
    principal = []
    for j in range(evals.size):
        v = evecs[:, j]
        v = v if v[np.argmax(np.abs(v))] > 0 else -v
        psd, qsd = math.sqrt(max(float(evals[j]), 0.0)), lv.prior_sd_along(v)
        row = {
            "sd": psd,
            "prior_sd": qsd,
            "ratio": psd / qsd if qsd > 0 else math.nan,
            "loadings": {n: float(v[i]) for i, n in enumerate(lv.names)},
        }
        if v_scale is not None:
            row["scale_alignment"] = float(abs(v @ v_scale))
        principal.append(row)
    principal.sort(key=lambda r: -r["ratio"] if math.isfinite(r["ratio"]) else math.inf)
    return principal


def _anchors(names, prior: Prior, measurements: Mapping) -> list[str]:
    """What pins each scaled parameter that the fit does not estimate freely: a measurement, a fixed
    value, or Table 3."""
    anchors = []
    for n in SCALED:
        if n in measurements:
            m, s = measurements[n]
            anchors.append(f"measured {n} = {m:g} +- {s:g} {PARAM_UNITS[n]}")
        elif n in prior.fixed:
            anchors.append(f"fixed {n} = {prior.fixed[n]:g} {PARAM_UNITS[n]}")
        elif n not in names:
            anchors.append(f"{n} held at Table 3 ({getattr(TABLE3, n):g} {PARAM_UNITS[n]})")
    return anchors


def _common_scale(
    lv: _LogView, w: np.ndarray, v_scale: np.ndarray, free: tuple[str, ...], names, prior: Prior, measurements: Mapping
) -> tuple[dict, bool]:
    """(c) The posterior along the common scale against the prior and against the box's ray through the
    posterior mean, the mass at the ray's ends, and whether the prior's box sets the scale; and whether the
    posterior piles against an end of the ray."""
    k = len(free)
    idx = [lv.names.index(n) for n in free]
    rate = math.sqrt(k)
    with np.errstate(divide="ignore"):  # a lower bound of 0 (p_sub) bounds nothing in log
        llo = np.log(np.array([prior.lo[names.index(n)] for n in free]))
    lhi = np.log(np.array([prior.hi[names.index(n)] for n in free]))

    def ray(x):  # extent along the scale direction of the ray through log point(s) x, in s units
        d_lo = np.max(llo - x[..., idx], axis=-1)
        d_hi = np.min(lhi - x[..., idx], axis=-1)
        return rate * d_lo, rate * d_hi

    s_lo, s_hi = ray(lv.mean)
    ray_len = float(s_hi - s_lo)
    ray_sd = _ray_sd(ray_len, rate)
    post_sd = float(math.sqrt(max(float(v_scale @ lv.cov @ v_scale), 0.0)))
    q_sd = lv.prior_sd_along(v_scale)
    a_lo, a_hi = ray(lv.L)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = -a_lo / (a_hi - a_lo)
    edge = (float(np.sum(w[u < EDGE_FRACTION])), float(np.sum(w[u > 1.0 - EDGE_FRACTION])))
    edge_expected = _ray_end_mass(rate, ray_len, EDGE_FRACTION)
    piled = any(e > EDGE_MASS_WARN and e > 2.5 * x for e, x in zip(edge, edge_expected))
    measured = [n for n in free if n in measurements]
    exact = k == len(SCALED) and not measured
    ray_ratio = post_sd / ray_sd if ray_sd > 0 else math.nan
    set_by_prior = exact or ray_ratio > SCALE_RATIO_WARN or piled
    return (
        {
            "names": list(free),
            "direction": {n: float(v_scale[i]) for i, n in enumerate(lv.names) if v_scale[i]},
            "posterior_sd": post_sd,
            "prior_sd": q_sd,
            "ratio": post_sd / q_sd if q_sd > 0 else math.nan,
            "ray_prior_sd": ray_sd,
            "ray_ratio": ray_ratio,
            "ray_length": ray_len,
            "log_c_sd": post_sd / rate,
            "edge_mass": list(edge),
            "edge_mass_expected": list(edge_expected),
            "exact_symmetry": exact,
            "measured": measured,
            "set_by_prior": bool(set_by_prior),
        },
        piled,
    )


def _scale_warning(scale: dict, piled: bool, anchors: list[str]) -> str:
    """(d) The plain warning of a common scale that the prior's box sets (``scale``, ``piled`` from
    :func:`_common_scale`)."""
    free, measured, ray_ratio = scale["names"], scale["measured"], scale["ray_ratio"]
    edge = scale["edge_mass"]
    how = (
        f"the posterior sd along it is {ray_ratio:.0%} of what the prior box allows there"
        + (
            f", and {max(edge):.0%} of the posterior lies in the outer {EDGE_FRACTION:.0%} of the box along it"
            if piled
            else ""
        )
        + "; contact pressure scales with it and flow with its square root"
    )
    if measured:
        given = "; ".join(a for a in anchors if a.startswith("measured"))
        subject = f"the measurements ({given}) narrow" if len(measured) > 1 else f"the measurement ({given}) narrows"
        return (
            f"COMMON SCALE: {subject} the common scale of {', '.join(free)} only partly ({how}): absolute "
            "moduli, p_sub, contact pressure and flow still rest partly on the prior's box along the common "
            "scale; a tighter measurement, or a second one (--measure rho=MEAN:SD), would anchor them "
            "(docs/inference.md, 'The common scale')"
        )
    if scale["exact_symmetry"]:
        why = "a GAW cannot determine the common scale of E_body, E_cover, E_lig, p_sub, rho and eta"
    elif ray_ratio > SCALE_RATIO_WARN:
        why = f"the data barely determine the common scale of {', '.join(free)}" + (
            f" ({'; '.join(anchors)} anchor{'s' if len(anchors) == 1 else ''} it only weakly)" if anchors else ""
        )
    else:
        why = f"the posterior is pressed against the prior's box along the common scale of {', '.join(free)}"
    return (
        f"COMMON SCALE: {why} ({how}): absolute moduli, p_sub, contact pressure and flow are set by the "
        f"prior's box along the common scale; {ANCHOR_HINT} (docs/inference.md, 'The common scale')"
    )


def _combinations(lv: _LogView, w: np.ndarray, free: tuple[str, ...]) -> list[dict]:
    """The scale-invariant combinations of ``free`` (SI units): geometric mean, sd of the log, prior sd of
    the log, 90 % interval."""
    combinations = []
    for ex in scale_invariant_combinations(free):
        a = np.array([ex.get(n, 0.0) for n in lv.names])
        shift = sum(ex[n] * math.log(TO_SI[n]) for n in ex)
        vals = lv.L @ a + shift
        lm = float(w @ vals)
        lsd = float(math.sqrt(max(float(w @ (vals - lm) ** 2), 0.0)))
        qsd = lv.prior_sd_along(a)
        q = weighted_quantiles(vals, w, [0.05, 0.95])
        combinations.append(
            {
                "label": combination_label(ex),
                "exponents": dict(ex),
                "unit": _unit(ex),
                "value": math.exp(lm),
                "log_mean": lm,
                "log_sd": lsd,
                "prior_log_sd": qsd,
                "ratio": lsd / qsd if qsd > 0 else math.nan,
                "q05": math.exp(float(q[0])),
                "q95": math.exp(float(q[1])),
            }
        )
    return combinations


#: Per parameter: the outer fraction of the prior box (each end) and the posterior weight in it that counts
#: as a posterior piled against that bound (a flat posterior puts BOUND_FRACTION there).
BOUND_FRACTION = 0.02
BOUND_MASS_WARN = 0.20


def at_bounds(post, prior: Prior) -> list[dict]:
    """Parameters whose posterior weight piles against a bound of the prior's box: more than
    ``BOUND_MASS_WARN`` of the weight within ``BOUND_FRACTION`` of the box's width from the bound.

    Each row: ``name``, ``bound`` ("lower"/"upper"), ``value`` (the bound), ``mass``, ``mean``, ``sd``,
    ``warning`` (plain text). Per parameter, unlike the common-scale check of :func:`identify`, which looks
    along the one direction a GAW cannot see: a fit the model cannot make presses single parameters to
    their bounds (:ref:`inference`, "The model's reach")."""
    names = tuple(post.names)
    if names != tuple(prior.names):
        raise ValueError(f"posterior parameters {names} differ from the prior's {prior.names}")
    X = np.atleast_2d(np.asarray(post.samples, dtype=float))
    w = np.asarray(post.weights, dtype=float)
    keep = w > 0
    if not keep.any():
        return []
    X, w = X[keep], w[keep] / np.sum(w[keep])
    lo, hi = prior.lo, prior.hi
    mean, cov = _wmean_cov(X, w)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    rows = []
    for i, n in enumerate(names):
        edge = BOUND_FRACTION * (hi[i] - lo[i])
        for side, b, mass in (
            ("lower", lo[i], float(np.sum(w[X[:, i] <= lo[i] + edge]))),
            ("upper", hi[i], float(np.sum(w[X[:, i] >= hi[i] - edge]))),
        ):
            if mass > BOUND_MASS_WARN:
                u = PARAM_UNITS[n]
                rows.append(
                    {
                        "name": n,
                        "bound": side,
                        "value": float(b),
                        "mass": mass,
                        "mean": float(mean[i]),
                        "sd": float(sd[i]),
                        "warning": (
                            f"AT PRIOR BOUND: {n} = {mean[i]:.5g} +- {sd[i]:.3g} {u}: {mass:.0%} of the posterior "
                            f"lies within {BOUND_FRACTION:.0%} of the prior's {side} bound {b:g} {u} (box "
                            f"[{lo[i]:g}, {hi[i]:g}]); the prior, not the data, stops it there, so the "
                            "estimate and its sd are not measurements: widen that bound (--prior), or check "
                            "the recording against the model's reach (vfinfer reach --check; "
                            'docs/inference.md, "The model\'s reach")'
                        ),
                    }
                )
    return rows


__all__ = [
    "SCALED",
    "BOUND_FRACTION",
    "BOUND_MASS_WARN",
    "Identifiability",
    "at_bounds",
    "identify",
    "format_identifiability",
    "scale_invariant_combinations",
    "combination_label",
    "uniform_log_moments",
]
