"""The job spec the command line builds from its options (``vfinfer infer`` on this machine, ``vfinfer submit`` to
a service): one validation for both, every bad input one ``error:`` line and exit 2 (``cli_common``)."""

from __future__ import annotations

from pathlib import Path

from rich.console import Console

from .cli_common import fail, load_gaw
from .cli_options import parse_fixed, parse_measurements, parse_priors, parse_screen

console = Console()


def build_spec(
    gaw: Path,
    fps: float | None,
    sampler: str,
    n: int,
    particles: int,
    mesh: str,
    dt: float,
    duration: float,
    discard: float,
    sigma_e: float,
    seed: int,
    prior: list[str] | None,
    fix: list[str] | None,
    chunk_size: int | None = None,
    model: str = "fe",
    noise: str = "fixed",
    measure: list[str] | None = None,
    force_reach: bool = False,
    screen: str | None = None,
    prior_set: str = "paper",
    area_scale: list[float] | None = None,
    contact: str = "projection",
    contact_layer_mm: float = 0.1,
    runs: int = 1,
):
    """A validated JobSpec from CLI options; every bad input is one ``error:`` line and exit 2.
    ``area_scale``: the job's ``area_scale`` box (``parse_area_scale``; None: calibrated areas)."""
    from pydantic import ValidationError

    from worker.jobspec import JobSpec

    measurements = parse_measurements(measure)
    priors = parse_priors(prior)
    fixed = parse_fixed(fix)
    both = sorted(set(priors) & set(fixed))
    if both:
        raise fail(f"{', '.join(both)}: given both --prior and --fix")
    if not discard < duration:
        raise fail(f"--discard ({discard:g} s) must be shorter than --duration ({duration:g} s)")
    g = load_gaw(gaw, fps)
    if g.fps * dt > 1.0:
        raise fail(
            f"--dt {dt:g} s simulates {1 / dt:.0f} steps/s, fewer than the recording's {g.fps:g} frames/s; "
            f"use --dt <= {1 / g.fps:.3g}"
        )
    scr = parse_screen(screen)
    if scr is not None and sampler != "smc":
        raise fail("--screen needs --sampler smc (it screens the SMC moves)")
    if runs != 1 and sampler != "smc":
        raise fail("--runs needs --sampler smc (it pools independent SMC runs)")
    smp = {"kind": "is", "n_samples": n} if sampler == "is" else {"kind": "smc", "n_particles": particles, "runs": runs}
    if scr is not None:
        smp["screen"] = scr
    body = {
        "model": model,
        "gaw": {"areas": [float(a) for a in g.area], "fps": float(g.fps), "units": "mm2"},
        "priors": priors or None,
        "fixed": fixed,
        "prior_set": prior_set,
        "sampler": smp,
        "mesh": mesh,
        "dt": dt,
        "duration": duration,
        "discard": discard,
        "sigma_e": sigma_e,
        "noise": noise,
        "seed": seed,
        "chunk_size": chunk_size,
        "measurements": measurements,
        "force_reach": bool(force_reach),
        "contact": contact,
        "contact_layer_mm": contact_layer_mm,
    }
    if area_scale is not None:
        body["area_scale"] = list(area_scale)
    try:
        return JobSpec.model_validate(body)
    except ValidationError as exc:
        msgs = [
            f"{'.'.join(map(str, e['loc'])) or 'input'}: {e['msg'].removeprefix('Value error, ')}" for e in exc.errors()
        ]
        raise fail("invalid job: " + "; ".join(msgs)) from None


def note_is(sampler: str) -> None:
    if sampler == "is":
        console.print(
            "note: importance sampling from the prior is the paper's method; beyond one or two free "
            "parameters its effective sample size collapses (the run warns when it does); the default "
            "--sampler smc needs far fewer simulations",
            highlight=False,
        )
