"""The options the ``vfinfer`` commands share, each with its unit and checked type, and the parsers of
the repeatable ``NAME=...`` options (every bad value is one ``error:`` line, exit 2)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Optional

import typer

from .cli_common import NON_NEGATIVE, POSITIVE, choice, fail

#: vfcore.config's CONTACTS and ELEMENTS, spelled here because importing vfcore costs the command line ~0.6 s at
#: start (its numba kernels); tests/service/test_cli_conventions.py checks they agree
CONTACTS = ("projection", "layer")
ELEMENTS = ("p1", "anp")

Fps = Annotated[
    Optional[float],
    typer.Option(
        parser=POSITIVE,
        help="camera frame rate, frames/s; needed only when the file has neither a time column nor a '# fps:' line",
    ),
]
Sampler = Annotated[
    str,
    typer.Option(
        parser=choice("smc", "is"),
        metavar="[smc|is]",
        help="'smc': adaptive, likelihood-tempered SMC (default, far fewer "
        "simulations); 'is': importance sampling from the prior (the paper's)",
    ),
]
N = Annotated[int, typer.Option("--n", min=1, help="--sampler is: prior draws, = simulations")]
Particles = Annotated[int, typer.Option(min=10, help="--sampler smc: particles per generation (>= 10)")]
Runs = Annotated[
    int,
    typer.Option(
        min=1,
        max=8,
        help="--sampler smc: independent runs, pooled (runs whose best particle lies more than 3 nats of "
        "log-likelihood below the best run's left out); a single run of a rugged six-parameter "
        "likelihood can miss the truth's basin (docs/inference.md, 'Independent runs'); cost x RUNS",
    ),
]
Mesh = Annotated[
    str,
    typer.Option(
        parser=choice("coarse", "medium", "fine"),
        metavar="[coarse|medium|fine]",
        help="finite-element mesh: coarse (~172 triangles), medium (the paper's), fine",
    ),
]
Dt = Annotated[
    float,
    typer.Option(parser=POSITIVE, help="simulation time step, s (the paper's 5e-5); 1/dt must reach the frame rate"),
]
Contact = Annotated[
    str,
    typer.Option(
        parser=choice(*CONTACTS),
        metavar="[" + "|".join(CONTACTS) + "]",
        help="midline contact: 'projection' (the paper's rigid midline with an inelastic impact; its peak pressures grow "
        "as --dt shrinks) or 'layer' (a thin compliant layer with the cover's modulus and viscosity: peak pressures "
        "converge in dt and the likelihood is smoother in the parameters; docs/model.md, 'Contact')",
    ),
]
Element = Annotated[
    str,
    typer.Option(
        parser=choice(*ELEMENTS),
        metavar="[" + "|".join(ELEMENTS) + "]",
        help="finite element: 'p1' (the paper's linear triangle) or 'anp' (averaged nodal dilatation, free of locking; "
        "docs/model.md, 'Locking and mesh convergence')",
    ),
]
ContactLayer = Annotated[
    float,
    typer.Option(
        "--contact-layer-mm", parser=POSITIVE, help="thickness of the contact layer, mm, in (0, 1) (--contact layer)"
    ),
]
Duration = Annotated[float, typer.Option(parser=POSITIVE, help="simulated time per run, s (the paper's 0.55)")]
Discard = Annotated[
    float, typer.Option(parser=NON_NEGATIVE, help="initial transient discarded before comparing, s (< --duration)")
]
SigmaE = Annotated[
    float,
    typer.Option(
        parser=POSITIVE, help="observation noise sd of the GAW, mm^2 (paper Eq. 15; ignored with --noise marginal)"
    ),
]
Seed = Annotated[int, typer.Option(min=0, help="random seed (>= 0); the same seed gives the same result")]
Prior = Annotated[
    Optional[list[str]],
    typer.Option(
        "--prior",
        help="NAME=LO:HI, a uniform prior box in paper units (E_body kPa, E_cover Pa, E_lig kPa, p_sub Pa, "
        "rho kg/m^3, eta Poise, x0 mm), repeatable; default: the paper's Table 2",
    ),
]
PriorSet = Annotated[
    str,
    typer.Option(
        "--prior-set",
        parser=choice("paper", "human"),
        metavar="[paper|human]",
        help="default prior bounds: 'paper' (Table 2, a silicone fold; 90 % of its phonating draws at 57-73 Hz) or "
        "'human' (human tissue; 99-232 Hz; docs/inference.md, 'Prior sets'); --prior overrides single parameters",
    ),
]
Fix = Annotated[
    Optional[list[str]],
    typer.Option("--fix", help="NAME=VALUE in paper units (as for --prior), repeatable: held fixed, not estimated"),
]
Url = Annotated[str, typer.Option(envvar="VFINFER_URL", help="service URL, http(s)://host:port")]
Token = Annotated[Optional[str], typer.Option(envvar="VFINFER_TOKEN", help="bearer token (or $VFINFER_TOKEN)")]


def _model(value) -> str:
    # the registry is read when the option is parsed: models registered by tests are valid there
    from worker.models import model_names

    return choice(*model_names())(value)


Model = Annotated[
    str,
    typer.Option(parser=_model, metavar="[fe]", hidden=True, help="'fe' or another registered model (worker.models)"),
]
Noise = Annotated[
    str,
    typer.Option(
        parser=choice("fixed", "marginal"),
        metavar="[fixed|marginal]",
        help="'fixed': the likelihood uses --sigma-e (paper, Eq. 15); 'marginal': the noise sd is unknown and "
        "integrated out (log-uniform, 0.01-100 mm^2)",
    ),
]
ForceReach = Annotated[
    bool,
    typer.Option(
        "--force-reach",
        help="fit even when the recording lies outside the model's reach (its f0 or peak area beyond "
        "every prior-predictive draw); without it such a recording exits 2 before sampling",
    ),
]
Measure = Annotated[
    Optional[list[str]],
    typer.Option(
        "--measure",
        help="NAME=MEAN:SD (paper units), repeatable: a Gaussian measurement of an estimated parameter, "
        "e.g. p_sub=1000:50; anchors the common scale a GAW cannot determine",
    ),
]
Screen = Annotated[
    Optional[str],
    typer.Option(
        "--screen",
        metavar="MESH[:DT]",
        help="--sampler smc: delayed acceptance; each proposal is first scored by the "
        "model on MESH with time step DT s (default 1e-4) and only the survivors "
        "are simulated with the full model, e.g. coarse:1e-4",
    ),
]
#: ``--uncalibrated``: the area scale's default box, a px/mm wrong by up to a factor 2 either way (k = 1/4 .. 4)
UNCALIBRATED_AREA_SCALE = (0.25, 4.0)
AreaScale = Annotated[
    Optional[str],
    typer.Option(
        "--area-scale",
        metavar="LO:HI",
        help="the recording's px/mm is not known: its areas are k times the true ones, k uniform on [LO, HI] (0 < LO < "
        "HI), integrated out of the likelihood and reported (k = (true px/mm / assumed px/mm)^2)",
    ),
]
Uncalibrated = Annotated[
    bool, typer.Option("--uncalibrated", help="as --area-scale 0.25:4: a px/mm wrong by up to a factor 2 either way")
]
Workers = Annotated[int, typer.Option(min=1, help="local worker processes")]
Out = Annotated[Path, typer.Option("--out", "-o", help="output folder (written whole at the end, or not at all)")]
Overwrite = Annotated[bool, typer.Option("--overwrite", help="replace an existing output folder of an earlier run")]


def _number(text: str, what: str) -> float:
    try:
        x = float(text.strip())
    except ValueError:
        raise fail(f"{what}: {text.strip()!r} is not a number") from None
    if not math.isfinite(x):
        raise fail(f"{what}: {text.strip()!r} is not a finite number")
    return x


def _name(name: str, opt: str, item: str) -> str:
    from vfcore.params import PARAM_NAMES

    name = name.strip()
    if name not in PARAM_NAMES:
        raise fail(f"{opt} {item!r}: unknown parameter {name!r}; known: {', '.join(PARAM_NAMES)}")
    return name


def parse_fixed(items: list[str] | None, opt: str = "--fix") -> dict[str, float]:
    """``NAME=VALUE`` items -> ``{name: value}`` (paper units)."""
    out: dict[str, float] = {}
    for it in items or []:
        k, sep, v = it.partition("=")
        if not sep:
            raise fail(f"{opt} must look like NAME=VALUE, got {it!r}")
        k = _name(k, opt, it)
        if k in out:
            raise fail(f"{opt} {k} given twice")
        out[k] = _number(v, f"{opt} {k}")
    return out


def parse_priors(items: list[str] | None) -> dict[str, list[float]]:
    """``NAME=LO:HI`` items -> ``{name: [lo, hi]}`` (paper units, lo < hi)."""
    out: dict[str, list[float]] = {}
    for it in items or []:
        k, sep, v = it.partition("=")
        lo, sep2, hi = v.partition(":")
        if not sep or not sep2:
            raise fail(f"--prior must look like NAME=LO:HI (paper units, e.g. p_sub=500:2000), got {it!r}")
        k = _name(k, "--prior", it)
        if k in out:
            raise fail(f"--prior {k} given twice")
        a, b = _number(lo, f"--prior {k} LO"), _number(hi, f"--prior {k} HI")
        if not a < b:
            raise fail(f"--prior {k}: LO ({a:g}) must be < HI ({b:g})")
        out[k] = [a, b]
    return out


def parse_measurements(items: list[str] | None) -> dict[str, list[float]]:
    """``--measure NAME=MEAN:SD`` (paper units, repeatable) -> ``{name: [mean, sd]}``; the values are checked by
    :func:`vfcore.inference.problem.validate_measurements`, as in a job spec."""
    from vfcore.inference.problem import validate_measurements

    out: dict[str, list[float]] = {}
    for it in items or []:
        name, sep, rest = it.partition("=")
        name = name.strip()
        mean_s, sep2, sd_s = rest.partition(":")
        if not sep or not sep2:
            raise fail(f"--measure must look like NAME=MEAN:SD (paper units, e.g. p_sub=1000:50), got {it!r}")
        if name in out:
            raise fail(f"--measure {name} given twice")
        try:
            out[name] = [float(mean_s), float(sd_s)]
        except ValueError:
            raise fail(f"--measure {name}: MEAN and SD must be numbers, got {rest!r}") from None
    try:
        validate_measurements(out)
    except ValueError as exc:
        raise fail(f"--measure: {exc}") from None
    return out


def parse_screen(text: str | None) -> dict | None:
    """``MESH[:DT]`` -> the job spec's ``sampler.screen`` (None when not given)."""
    if text is None:
        return None
    mesh, _, dt = text.partition(":")
    mesh = mesh.strip()
    if mesh not in ("coarse", "medium", "fine"):
        raise fail(f"--screen {text!r}: mesh must be coarse, medium or fine")
    out = {"mesh": mesh}
    if dt.strip():
        x = _number(dt, f"--screen {text!r}")
        if not 0 < x <= 1e-3:
            raise fail(f"--screen {text!r}: the time step must lie in (0, 1e-3] s")
        out["dt"] = x
    return out


def parse_area_scale(text: str | None, uncalibrated: bool = False) -> list[float] | None:
    """``--area-scale LO:HI`` / ``--uncalibrated`` -> the job spec's ``area_scale`` (None: calibrated areas)."""
    if text is None:
        return list(UNCALIBRATED_AREA_SCALE) if uncalibrated else None
    if uncalibrated:
        raise fail("give --area-scale LO:HI or --uncalibrated (= --area-scale 0.25:4), not both")
    lo, sep, hi = text.partition(":")
    if not sep:
        raise fail(f"--area-scale must look like LO:HI (e.g. 0.25:4), got {text!r}")
    a, b = _number(lo, "--area-scale LO"), _number(hi, "--area-scale HI")
    if not 0 < a < b:
        raise fail(f"--area-scale {text!r}: needs 0 < LO < HI")
    return [a, b]
