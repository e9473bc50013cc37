"""``vfinfer diagnose GAW``: which physics is the model missing? (vfcore.diagnose on this machine).

Its settings are the API's :class:`~service.api_models.DiagnoseRequest` (one set of defaults and bounds for the
command line and the service) and it calls the diagnosis as the service does (:func:`service.diagnosis.run_diagnose`).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.table import Table

from vfcore.config import contact_label

from .cli_common import NON_NEGATIVE, POSITIVE, ProgressLines, choice, fail, load_gaw, warnings_in_words
from .cli_options import AreaScale, Contact, ContactLayer, PriorSet, Uncalibrated, parse_area_scale
from vfcore.diagnose.defaults import DEFAULT_ESTIMATE, DISCARD_S, DURATION_S
from vfcore.diagnose.options import REFIT_STARTS, DiagnoseOptions

#: the library's settings are the command's defaults (one source for library, CLI and service)
DEFAULTS = DiagnoseOptions()

console = Console()


def _fail(msg: str) -> typer.Exit:
    return fail(msg)


def _names(text: str | None) -> list[str]:
    return [n.strip() for n in (text or "").split(",") if n.strip()]


def diagnose_request(**given):
    """The diagnosis settings given on the command line (None: not given, the default), checked with the API's
    bounds; a bad one is one ``error:`` line naming its option, exit 2."""
    from pydantic import ValidationError

    from .api_models import DIAGNOSIS_OPTIONS, DiagnoseRequest

    try:
        return DiagnoseRequest(**{k: v for k, v in given.items() if v is not None})
    except ValidationError as exc:
        e = exc.errors()[0]
        field = str(e["loc"][0]) if e["loc"] else "settings"
        raise _fail(f"{DIAGNOSIS_OPTIONS.get(field, field)}: {e['msg'].removeprefix('Value error, ')}") from None


def _f(x, fmt: str = ".4g") -> str:
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, fmt)


def stage_line(ev: dict) -> str:
    """One line for a progress event of :mod:`vfcore.diagnose.progress`."""
    where = ev["stage"] + (f" {ev['step']}/{ev['steps']}" if ev.get("step") and ev.get("steps") else "")
    what = f": {ev['entry']}" if ev.get("entry") else ""
    m, sec = divmod(int(ev["elapsed_s"]), 60)
    return f"{m:3d}:{sec:02d}  {where}{what} · {ev['simulations']:,} simulations"


class StageReporter:
    """The command's progress: a line at each new stage, and a status line that follows the
    simulations (shown on a terminal only)."""

    def __init__(self, status=None, lines=None):
        self.status = status
        self.lines = lines  # cli_common.ProgressLines: stderr that is not a terminal
        self.last = None

    def __call__(self, ev: dict) -> None:
        key = (ev["stage"], ev.get("entry"))
        if key != self.last:
            self.last = key
            console.print(stage_line(ev), highlight=False)
        if self.status is not None:
            self.status.update(stage_line(ev))
        if self.lines is not None:
            where = ev["stage"] + (f" {ev['step']}/{ev['steps']}" if ev.get("step") and ev.get("steps") else "")
            self.lines.update(where + (f" ({ev['entry']})" if ev.get("entry") else ""), ev["simulations"])


def build_problem(
    gaw: Path,
    fps: float | None,
    estimate: str,
    fix: list[str] | None,
    mesh: str,
    dt: float,
    duration: float,
    discard: float,
    sigma_e: float,
    noise: str = "fixed",
    prior_set: str = "paper",
    area_scale: list[float] | None = None,
    contact: str = "projection",
    contact_layer_mm: float = 0.1,
):
    """The Problem of the command's options; every bad input raises ``typer.Exit(2)`` with a red line.
    ``prior_set``: the default bounds of the estimated parameters; ``area_scale``: the box of an unknown area
    scale (``parse_area_scale``; None: calibrated areas); ``contact``, ``contact_layer_mm``: the midline law."""
    from vfcore.config import MESHES, SimConfig
    from vfcore.inference import Prior
    from vfcore.inference.problem import Problem
    from vfcore.params import PARAM_NAMES, TABLE3

    est = list(dict.fromkeys(_names(estimate)))
    bad = [n for n in est if n not in PARAM_NAMES]
    if bad:
        raise _fail(f"--estimate: unknown parameter(s) {bad}; known: {list(PARAM_NAMES)}")
    if not est:
        raise _fail("--estimate: no parameter to estimate")
    fixed = TABLE3.as_dict()
    for item in fix or []:
        k, sep, v = item.partition("=")
        k = k.strip()
        if not sep:
            raise _fail(f"--fix must look like NAME=VALUE, got {item!r}")
        if k not in PARAM_NAMES:
            raise _fail(f"--fix: unknown parameter {k!r}; known: {list(PARAM_NAMES)}")
        if k in est:
            raise _fail(f"--fix: {k!r} is also in --estimate")
        try:
            val = float(v)
        except ValueError:
            raise _fail(f"--fix {k}: {v.strip()!r} is not a number") from None
        if not math.isfinite(val):
            raise _fail(f"--fix {k}: value must be finite")
        fixed[k] = val
    for k in est:
        fixed.pop(k)
    if mesh not in MESHES:
        raise _fail(f"--mesh must be one of {list(MESHES)}, got {mesh!r}")
    if not (dt > 0 and duration > 0 and 0 <= discard < duration):
        raise _fail(
            f"need dt > 0, duration > 0 and 0 <= discard < duration "
            f"(got dt={dt}, duration={duration}, discard={discard})"
        )
    if not sigma_e > 0:
        raise _fail(f"--sigma-e must be > 0, got {sigma_e}")
    g = load_gaw(gaw, fps)
    if g.fps * dt > 1.0:
        raise _fail(f"--dt: camera fps {g.fps:g} exceeds the simulation rate 1/dt={1 / dt:.0f}")
    try:
        prior = Prior.default(fixed=fixed, prior_set=prior_set)
        problem = Problem(
            obs_gaw=g.area,
            fps=float(g.fps),
            prior=prior,
            sigma_e=float(sigma_e),
            noise=noise,
            config=SimConfig(
                mesh=mesh,
                dt=dt,
                duration=duration,
                discard=discard,
                fps=float(g.fps),
                contact=contact,
                contact_layer_mm=contact_layer_mm,
            ),
            area_scale=None if area_scale is None else tuple(area_scale),
        )
    except ValueError as exc:
        raise _fail(f"invalid GAW or settings ({gaw}): {exc}") from None
    return problem


def _p(p) -> str:
    if p is None or (isinstance(p, float) and not math.isfinite(p)):
        return "-"
    return f"[red]{p:.3f} *[/red]" if p < 0.05 else f"{p:.3f}"


def measures_table(d: dict) -> None:
    """GAW measures of the recording against the base fit's (and the named extension's) replicated
    recordings: predicted mean and two-sided posterior-predictive p-value, * below 0.05."""
    b = d["base"]
    meas = b.get("measures")
    if not meas:
        return
    win = d.get("winner")
    a = (d.get("refits") or {}).get(win) if win else None
    t = Table(
        title="GAW measures (posterior-predictive two-sided p; * p < 0.05; replicate noise "
        f"{_f(b.get('predictive_noise_sd'), '.3g')} mm^2, from the recording)"
    )
    t.add_column("measure")
    for col in ("recording", "base predicts", "base p") + ((f"{win} predicts", f"{win} p") if a else ()):
        t.add_column(col, justify="right")
    for k, m in meas.items():
        row = [k, _f(m.get("observed")), _f(m.get("predicted")), _p(b["pvalues"].get(k))]
        if a:
            am = (a.get("measures") or {}).get(k, {})
            row += [_f(am.get("predicted")), _p((a.get("pvalues") or {}).get(k))]
        t.add_row(*row)
    console.print(t)


def print_report(d: dict) -> None:
    """Rich tables of a ``DiagnoseReport.to_dict()`` (after :func:`jsonable`)."""
    b = d["base"]
    t = Table(title="Base fit")
    for col in ("residual RMS (mm^2)", "log-evidence", "dominant phase", "simulations"):
        t.add_column(col, justify="right")
    t.add_row(
        _f(b["residual_rms"]),
        f"{_f(b['log_evidence'], '.2f')} +- {_f(b['log_evidence_se'], '.2f')}",
        str(b["dominant_phase"]),
        str(b["n_simulations"]),
    )
    console.print(t)
    s = Table(title="Screening (best log-likelihood gain at base particles, nats)")
    s.add_column("candidate")
    s.add_column("score", justify="right")
    s.add_column("best parameters")
    s.add_column("simulations", justify="right")
    scr = {k: v for k, v in d["screening"].items() if not k.startswith("_")}
    for name, v in sorted(scr.items(), key=lambda kv: -(kv[1]["score"] if kv[1]["score"] is not None else -1e300)):
        phi = ", ".join(f"{k}={_f(x)}" for k, x in (v.get("best_phi") or {}).items()) or "-"
        s.add_row(name, _f(v["score"], ".2f"), phi, str(v["n_simulations"]))
    console.print(s)
    if d["refits"]:
        rows = {r["name"]: r for r in d["ranking"]}
        r = Table(title="Refits (base + extension; waveform-level parameters integrated per simulation)")
        for col in ("extension", "dlogZ", "residual RMS", "RMS improvement", "extension parameters", "found"):
            r.add_column(col, justify="left" if col in ("extension", "extension parameters") else "right")
        from vfcore.diagnose.extensions import get

        for name, a in d["refits"].items():
            rk = rows.get(name, {})
            ext = set(get(name).param_names)
            pars = (
                ", ".join(f"{k}={_f(v['mean'])} +- {_f(v['sd'], '.2g')}" for k, v in a["params"].items() if k in ext)
                or "-"
            )
            imp = a.get("rms_improvement")
            r.add_row(
                name,
                f"{_f(rk.get('delta'), '.2f')} +- {_f(rk.get('delta_se'), '.2f')}",
                _f(a["residual_rms"]),
                "-" if imp is None else f"{100 * imp:.1f} %",
                pars,
                "yes" if rk.get("found") else "no",
            )
        console.print(r)
    measures_table(d)
    for n in d.get("notes") or []:
        console.print(f"[yellow]note[/yellow] {n}", highlight=False)
    colour = "green" if d.get("winner") else "bold"
    console.print(f"[{colour}]{d['verdict']}[/{colour}]", highlight=False)
    console.print(f"{d['n_simulations']} simulations, wall time {d['wall_s']:.1f} s")
    by = (d.get("cost") or {}).get("by_stage") or {}
    if by:
        console.print(
            "time by stage: "
            + ", ".join(
                f"{k} {_f(v.get('wall_s'), '.0f')} s"
                for k, v in sorted(by.items(), key=lambda kv: -(kv[1].get("wall_s") or 0))
            ),
            highlight=False,
        )


def diagnose_cmd(
    gaw: Annotated[Path, typer.Argument(help="GAW file (CSV as written by 'vfinfer simulate'/'gaw', NPY, NPZ)")],
    out: Annotated[Path, typer.Option(help="output folder (diagnosis.json, diagnosis.png, index.html)")],
    fps: Annotated[
        Optional[float], typer.Option(parser=POSITIVE, help="camera frame rate, frames/s, if the file does not say")
    ] = None,
    estimate: Annotated[
        str,
        typer.Option(
            help="comma-separated parameters to estimate (default: the five "
            "combinations a GAW determines, rho anchoring the scale)"
        ),
    ] = DEFAULT_ESTIMATE,
    fix: Annotated[
        Optional[list[str]],
        typer.Option(
            "--fix",
            help="NAME=VALUE (paper units), repeatable; parameters neither estimated nor fixed take Table 3 values",
        ),
    ] = None,
    mesh: Annotated[
        Optional[str],
        typer.Option(
            parser=choice("coarse", "medium", "fine"),
            metavar="[coarse|medium|fine]",
            help="finite-element mesh (default: coarse, or the --base fit's)",
        ),
    ] = None,
    dt: Annotated[
        Optional[float],
        typer.Option(parser=POSITIVE, help="simulation time step, s (default: 1e-4, or the --base fit's)"),
    ] = None,
    duration: Annotated[
        Optional[float],
        typer.Option(parser=POSITIVE, help=f"simulated time, s (default: {DURATION_S:g}, or the --base fit's)"),
    ] = None,
    discard: Annotated[
        Optional[float],
        typer.Option(
            parser=NON_NEGATIVE, help=f"initial transient discarded, s (default: {DISCARD_S:g}, or the --base fit's)"
        ),
    ] = None,
    sigma_e: Annotated[float, typer.Option(parser=POSITIVE, help="observation noise sd, mm^2")] = 1.0,
    noise: Annotated[
        str,
        typer.Option(
            parser=choice("fixed", "marginal"),
            metavar="[fixed|marginal]",
            help="'fixed' (--sigma-e) or 'marginal' (noise sd integrated out)",
        ),
    ] = "fixed",
    particles: Annotated[int, typer.Option(help="SMC particles of each base fit (10-400)")] = DEFAULTS.n_particles,
    refit_particles: Annotated[
        int, typer.Option(help="SMC particles of each extended fit (10-400)")
    ] = DEFAULTS.refit_particles,
    refit_start: Annotated[
        str,
        typer.Option(
            parser=choice(*REFIT_STARTS),
            metavar="[" + "|".join(REFIT_STARTS) + "]",
            help="where each extended fit's SMC starts: the prior, the base posterior (about a quarter fewer "
            "simulations, no rescue), or the base for observation-level entries only",
        ),
    ] = DEFAULTS.refit_start,
    max_refits: Annotated[
        Optional[int],
        typer.Option(help="most observation-level extensions refitted, best screened first (0-6; default: all)"),
    ] = DEFAULTS.max_refits,
    candidates: Annotated[
        Optional[str], typer.Option(help="comma-separated extensions to screen (default: every implemented one)")
    ] = None,
    continuation: Annotated[
        bool,
        typer.Option(
            help="also search the base model and every extension by window continuation and fit from the "
            "optimum (~2,000 simulations each; docs/diagnose.md section 4)"
        ),
    ] = DEFAULTS.continuation,
    base: Annotated[
        Optional[Path],
        typer.Option(
            help="a fitted posterior of this recording (posterior.nc of 'vfinfer infer' or of a job) to use as the "
            "base fit instead of fitting it again; one with fewer estimated parameters is the pinned fit "
            "that freeing the material parameters is judged against"
        ),
    ] = None,
    free_material: Annotated[
        bool,
        typer.Option(
            help="free the scaled parameters held at Table 3 (all but the anchor rho) before the catalogue is "
            "screened, and report whether they explain the mismatch"
        ),
    ] = DEFAULTS.free_material,
    workers: Annotated[int, typer.Option(help="local worker processes (1: in this process)")] = 2,
    resume: Annotated[
        bool,
        typer.Option(
            help="store finished simulations in OUT/.resume while running, so the same command run again "
            "after an interruption reads them back (same result, bit for bit); deleted once the "
            "diagnosis is written"
        ),
    ] = True,
    seed: Annotated[int, typer.Option(min=0, help="random seed (>= 0)")] = DEFAULTS.seed,
    prior_set: PriorSet = "paper",
    area_scale: AreaScale = None,
    uncalibrated: Uncalibrated = False,
    contact: Contact = None,
    contact_layer_mm: ContactLayer = None,
) -> None:
    """Fit the model, screen catalogued extensions, refit the promising ones and name the missing physics.
    With --base, the model settings not given on the command line are the fit's own."""
    from .diagnosis import plot

    req = diagnose_request(
        candidates=None if candidates is None else _names(candidates),
        n_particles=particles,
        refit_particles=refit_particles,
        refit_start=refit_start,
        max_refits=max_refits,
        continuation=continuation,
        seed=seed,
        free_material=free_material,
    )
    if workers < 1:
        raise _fail(f"--workers must be >= 1, got {workers}")
    if out.exists() and not out.is_dir():
        raise _fail(f"--out {out} exists and is not a folder")
    given = {
        "mesh": mesh,
        "dt": dt,
        "duration": duration,
        "discard": discard,
        "contact": contact,
        "contact_layer_mm": contact_layer_mm,
    }
    base_post = read_base(base) if base is not None else None
    m = model_settings(given, base_post)
    problem = build_problem(
        gaw,
        fps,
        estimate,
        fix,
        m["mesh"],
        m["dt"],
        m["duration"],
        m["discard"],
        sigma_e,
        noise,
        prior_set,
        parse_area_scale(area_scale, uncalibrated),
        m["contact"],
        m["contact_layer_mm"],
    )
    if base_post is not None:
        check_base(base_post, base, problem)
        taken = [
            f"{_OPTION[k]} {v:g}" if isinstance(v, float) else f"{_OPTION[k]} {v}"
            for k, v in m.items()
            if given[k] is None and v != MODEL_DEFAULTS[k]
        ]
        if taken:
            console.print("--base: simulating with the fit's " + ", ".join(taken), highlight=False)
    mesh = m["mesh"]

    console.print(
        f"diagnosing {gaw.name}: estimate {list(problem.prior.names)}, {req.n_particles} particles, "
        f"candidates {req.candidates or 'all implemented'}, {workers} worker(s)"
    )
    print_expected_cost(problem, req, workers, base_post)
    t0 = time.perf_counter()
    store = out / ".resume"
    if resume and store.exists():
        console.print(f"resuming: reading finished simulations back from {store}")
    d, report = run_local(problem, req, workers, store if resume else None, base_post)
    out.mkdir(parents=True, exist_ok=True)
    (out / "diagnosis.json").write_text(json.dumps(d, indent=1))
    plot(report, problem, out / "diagnosis.png")
    page = write_page(out, d, gaw, problem, sigma_e, noise, mesh)
    if resume:
        import shutil

        shutil.rmtree(store, ignore_errors=True)
    print_report(d)
    console.print(f"wrote {out / 'diagnosis.json'} and {out / 'diagnosis.png'} ({time.perf_counter() - t0:.1f} s)")
    console.print(f"report: {page.resolve()}", highlight=False, soft_wrap=True)


def print_expected_cost(problem, req, workers: int, base_post) -> None:
    """The diagnosis's expected cost, before it starts: the two outcomes' measured simulation ranges and
    minutes from a short timed probe of the recording's own model (:mod:`vfcore.diagnose.expected`)."""
    from vfcore.batch import probe_seconds_per_sim
    from vfcore.diagnose.expected import expected_for
    from vfcore.inference.importance import draw_prior

    opts = req.options()
    prior = problem.prior
    t = probe_seconds_per_sim(prior.full_array(draw_prior(prior, 32, opts.seed)), problem.config)
    for line in expected_for(problem, opts, t, workers, base_post).lines():
        console.print(line, highlight=False, soft_wrap=True)


def run_local(problem, req, workers: int, store: Path | None, base_post):
    """The diagnosis on this machine, in this process (``workers`` 1) or a process pool, its finished parts
    kept in ``store`` (None: not kept). Returns the report as JSON-able dict, with a resumed run's earlier
    attempts' time counted in, and the report itself; a failure is one ``error:`` line, exit 1."""
    from vfcore.inference.memo import CachedMap, account

    from vfcore.strict_json import jsonable

    from .diagnosis import run_diagnose

    try:
        with (
            console.status("starting", spinner="dots") as status,
            warnings_in_words() as raised,
            ProgressLines() as lines,
        ):
            if workers == 1:
                cmap = CachedMap(map, store) if store is not None else None
                report = run_diagnose(
                    problem, req, map=cmap or map, progress=StageReporter(status, lines), base=base_post
                )
            else:
                from concurrent.futures import ProcessPoolExecutor

                from vfcore.inference.importance import BalancedMap

                with ProcessPoolExecutor(workers) as pool:
                    cmap = CachedMap(pool.map, store) if store is not None else None
                    report = run_diagnose(
                        problem,
                        req,
                        map=BalancedMap(cmap or pool.map, workers),
                        progress=StageReporter(status, lines),
                        base=base_post,
                    )
    except Exception as exc:  # noqa: BLE001 - a failed run is reported, not a traceback
        raise fail(f"the diagnosis failed: {type(exc).__name__}: {exc}", code=1) from None
    d = jsonable(account(report.to_dict(), cmap))
    d["warnings"] = raised  # shown as they came; the report lists them
    return d, report


#: the option that sets each model setting a ``--base`` posterior must share with the diagnosis
_OPTION = {
    "mesh": "--mesh",
    "dt": "--dt",
    "duration": "--duration",
    "discard": "--discard",
    "fps": "--fps",
    "contact": "--contact",
    "contact_layer_mm": "--contact-layer-mm",
}


#: the model settings of a diagnosis given neither on the command line nor by a ``--base`` fit
MODEL_DEFAULTS = {
    "mesh": "coarse",
    "dt": 1e-4,
    "duration": DURATION_S,
    "discard": DISCARD_S,
    "contact": "projection",
    "contact_layer_mm": 0.1,
}


def model_settings(given: dict, base_post=None) -> dict:
    """The diagnosis's model settings: those ``given`` (not None), else the ``base_post`` fit's recorded ones
    (``Posterior.model``), else :data:`MODEL_DEFAULTS`. Adopting the fit's settings makes ``--base`` the same
    model as the extensions refitted against it without the user repeating them; a setting given that differs
    from the fit's is refused by :func:`check_base`."""
    rec = (base_post.model or {}) if base_post is not None else {}
    return {k: given[k] if given.get(k) is not None else rec.get(k, d) for k, d in MODEL_DEFAULTS.items()}


def load_base(path: Path, problem):
    """The ``--base`` posterior read (:func:`read_base`) and checked against the problem (:func:`check_base`)."""
    post = read_base(path)
    check_base(post, path, problem)
    return post


def read_base(path: Path):
    """The ``--base`` posterior: a NetCDF posterior of an FE fit with predictions; anything else is one error
    line."""
    from vfcore.inference.posterior import Posterior

    if not path.is_file():
        raise _fail(f"--base {path}: no such file")
    try:
        post = Posterior.from_netcdf(path)
    except Exception as exc:  # noqa: BLE001 - any unreadable file is one error line
        raise _fail(f"--base {path}: not a vfinfer posterior.nc ({type(exc).__name__}: {exc})") from None
    if post.predictive is None:
        raise _fail(f"--base {path}: the posterior carries no predicted GAWs (not a finite-element fit)")
    return post


def check_base(post, path: Path, problem) -> None:
    """``post`` (read from ``path``) against the problem: estimating the problem's parameters or some of them,
    of the same recording, simulated with the same model settings (where the file records them:
    ``Posterior.model``)."""
    import numpy as np

    diff = problem.config.differences(post.model or {})
    if diff:
        was = ", ".join(f"{_OPTION.get(k, k)} {a}" for k, (a, _) in diff.items())
        now = ", ".join(f"{_OPTION.get(k, k)} {b}" for k, (_, b) in diff.items())
        raise _fail(
            f"--base {path}: it was simulated with {was}; this diagnosis would simulate {now} "
            f"(leave {'/'.join(_OPTION.get(k, k) for k in diff)} out to take the fit's: the base and the extensions "
            "must be the same model)"
        )
    extra = sorted(set(post.names) - set(problem.prior.names))
    if extra:
        raise _fail(f"--base {path}: it estimates {extra}, which --estimate does not")
    obs = None if post.obs_gaw is None else np.asarray(post.obs_gaw, dtype=float)
    mine = np.asarray(problem.obs_compared, dtype=float)
    if obs is not None and not (obs.shape == mine.shape and np.allclose(obs, mine, rtol=0, atol=1e-9)):
        raise _fail(f"--base {path}: it was fitted to another recording (or another window of this one)")


def write_page(out: Path, d: dict, gaw: Path, problem, sigma_e: float, noise: str, mesh: str) -> Path:
    """``out/index.html``: the diagnosis report, with the recording and the settings it was run with."""
    from .report_diagnose import write_diagnosis_report

    source = {
        "recording": gaw.name,
        "camera frame rate": f"{problem.fps:g} frames/s",
        "estimated": ", ".join(problem.prior.names),
        "mesh": mesh,
        "contact": contact_label(problem.config.contact, problem.config.contact_layer_mm),
        "noise": f"{noise}" + (f", sigma_e = {sigma_e:g} mm²" if noise == "fixed" else ""),
    }
    return write_diagnosis_report(out, d, title=f"vfinfer diagnosis of {gaw.name}", source=source)
