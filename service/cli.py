"""``vfinfer`` command line: local inference, forward simulation, the model's reach, the service and the demo.

The client commands (submit, list, status, cancel, fetch, diagnosis, report) are in ``cli_client``, video -> GAW in
``cli_gaw``, the diagnosis in ``cli_diagnose``. Every user error is one ``error:`` line on stderr and exit 2
(``cli_common``)."""

from __future__ import annotations

import json
import os
import socket
import sys
import tempfile
import time
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console

from .cli_common import (
    POSITIVE,
    ProgressLines,
    VfinferGroup,
    check_out,
    fail,
    load_gaw,
    staged_output,
    warn,
    warnings_in_words,
)
from .cli_options import (
    AreaScale,
    Contact,
    ContactLayer,
    Discard,
    Dt,
    Duration,
    Element,
    Fix,
    Fps,
    ForceReach,
    Measure,
    Mesh,
    Model,
    N,
    Noise,
    Out,
    Overwrite,
    Particles,
    Prior,
    PriorSet,
    Runs,
    Sampler,
    Screen,
    Seed,
    SigmaE,
    Uncalibrated,
    Workers,
    parse_area_scale,
    parse_fixed,
    parse_priors,
)
from .cli_spec import build_spec, note_is
from .cli_tables import print_identifiability, print_table  # noqa: F401  (re-exported for callers)

app = typer.Typer(
    cls=VfinferGroup,
    add_completion=False,
    no_args_is_help=True,
    context_settings={"help_option_names": ["-h", "--help"]},
    help="Bayesian inference of vocal-fold properties from glottal area waveforms (GAW). "
    "Parameters in the paper's units: E_body kPa, E_cover Pa, E_lig kPa, p_sub Pa, rho kg/m^3, "
    "eta Poise, x0 mm; areas mm^2; times s. When stderr is not a terminal (a log file, nohup, a "
    "batch job), infer, diagnose, reach and demo print a plain 'progress:' line there every ~30 s "
    "(VFINFER_PROGRESS_INTERVAL, seconds) instead of the live bar.",
)
console = Console()

GawArg = Annotated[
    Path,
    typer.Argument(
        help="GAW file: CSV with a 'time_s,area_mm2' header (or one area column plus --fps), NPY or NPZ; "
        "areas in mm^2 (see README, 'Input')"
    ),
]
#: Store products and the files they become in an output folder.
PRODUCT_FILES = {
    "samples_csv": "samples.csv",
    "samples_meta": "samples.json",
    "posterior_nc": "posterior.nc",
    "gaw_fit": "gaw_fit.png",
    "corner": "corner.png",
    "contact_pressure": "contact_pressure.png",
}


def _version(value: bool) -> None:
    if value:
        from importlib.metadata import PackageNotFoundError, version

        try:
            v = version("vfinfer")
        except PackageNotFoundError:
            v = "unknown (not installed)"
        typer.echo(f"vfinfer {v}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        Optional[bool], typer.Option("--version", callback=_version, is_eager=True, help="print the version and exit")
    ] = None,
) -> None:
    """Bayesian inference of vocal-fold properties from glottal area waveforms."""


# ------------------------------------------------------------------------------------ helpers
def reach_gate(spec, force_reach: bool, workers: int = 1) -> None:
    """The reach check before any sampling (docs/inference.md, "The model's reach"): a recording outside the
    reach of the model and prior exits 2 with one ``error:`` line unless ``force_reach`` (then a warning);
    a marginal or unchecked one gets a warning; an inside one a one-line note. The ensemble is found or built
    first (:func:`ensure_reach`); the note and the warning say which it was."""
    from .cli_reach import ensure_reach

    which = ensure_reach(spec, workers)
    which = f" (reach ensemble: {which})" if which else ""
    try:
        v = spec.reach()
    except ValueError as exc:
        raise fail(f"reach check: {exc}") from None
    if v.verdict == "outside" and not force_reach:
        raise fail(v.message + "; --force-reach fits anyway")
    w = v.warning("--force-reach")
    if w is None:
        console.print(f"reach: {v.message}{which}", highlight=False, soft_wrap=True)
    elif spec.model == "fe":  # only the FE model has a reach to check
        warn(w + which)


def print_expected_cost(spec, workers: int) -> None:
    """The run's expected cost, before it starts: simulations (exact for IS, the measured range for SMC) and
    minutes on this machine from a short timed probe of the job's own model."""
    from worker.run import expected_simulations, probe_seconds_per_sim

    lo, hi = expected_simulations(spec)
    t = probe_seconds_per_sim(spec)
    span = f"{lo:,}" if lo == hi else f"{lo:,}-{hi:,}"
    m_lo, m_hi = lo * t / workers / 60.0, hi * t / workers / 60.0
    mins = f"{m_lo:.1f}" if lo == hi else f"{m_lo:.1f}-{m_hi:.1f}"
    per = "" if lo == hi else " (the range of SMC fits of 2 to 6 free parameters)"
    runs = getattr(spec.sampler, "runs", 1)
    if runs > 1:
        per += f" for {runs} independent runs"
    console.print(
        f"expected cost: {span} simulations{per} at {t * 1e3:.0f} ms each on this machine: about "
        f"{mins} min on {workers} worker{'s' if workers > 1 else ''}",
        highlight=False,
    )


def export_products(
    store_path: Path, out: Path, title: str = "vfinfer result", extra_warnings: list[str] | None = None
) -> dict:
    """Copy summary, samples (CSV + JSON metadata, NetCDF) and figures out of a job store into ``out`` and
    write the HTML report ``out/index.html``; ``extra_warnings`` (Python warnings the run raised here) join the
    summary's warnings, so that the report lists every warning the command prints."""
    from worker import store as st

    from .report import write_report

    out.mkdir(parents=True, exist_ok=True)
    summary = st.read_summary(store_path)
    known = summary.setdefault("warnings", [])
    known += [w for w in extra_warnings or [] if w not in known]
    (out / "posterior.json").write_text(json.dumps(summary, indent=1, sort_keys=True))
    (out / "posterior_table.txt").write_text(summary.get("formatted", "") + "\n")
    ident = summary.get("identifiability")
    if ident and not ident.get("error"):
        from vfcore.inference.identify import format_identifiability

        (out / "identifiability.txt").write_text(format_identifiability(ident) + "\n")
    for name, fname in PRODUCT_FILES.items():
        blob = st.read_blob(store_path, name)
        if blob is not None:
            (out / fname).write_bytes(blob)
    write_report(out, summary, title=title)
    return summary


def run_local(spec, out: Path, workers: int, job_id: str = "local") -> dict:
    """Run a job on an in-process LocalCluster with a progress bar (on a terminal) or a plain progress line every
    ~30 s on stderr (elsewhere: ``cli_common.ProgressLines``); products go to ``out``."""
    from distributed import Client, LocalCluster
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from worker.run import register_warm_up, run_job

    out.mkdir(parents=True, exist_ok=True)
    store_path = out / f"{job_id}.zarr"
    with (
        ProgressLines() as lines,
        LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None) as cl,
        Client(cl) as client,
        Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            TextColumn("{task.completed}/{task.total} sims  {task.fields[ess]}"),
            TimeElapsedColumn(),
            console=console,
        ) as bar,
    ):
        register_warm_up(client)
        task = bar.add_task("simulating", total=spec.n_simulations, ess="")
        lines.update("simulating", 0, spec.n_simulations)

        def report(p):
            bar.update(
                task,
                completed=p.n_done,
                total=max(p.n_total, p.n_done),
                description=p.phase,
                ess=f"ESS={p.ess:.1f}" if p.ess == p.ess else "",
            )
            lines.update(p.phase, p.n_done, max(p.n_total, p.n_done), p.ess)

        with warnings_in_words(echo=False) as raised:  # printed with the summary's warnings
            stats = run_job(client, job_id, store_path, spec, report=report)
    (out / "timings.json").write_text(json.dumps(stats, indent=1))
    return export_products(store_path, out, title=f"vfinfer {job_id}", extra_warnings=raised)


# ------------------------------------------------------------------------------------ commands
@app.command()
def infer(
    gaw: GawArg,
    fps: Fps = None,
    sampler: Sampler = "smc",
    n: N = 2000,
    particles: Particles = 200,
    mesh: Mesh = "coarse",
    dt: Dt = 5e-5,
    duration: Duration = 0.55,
    discard: Discard = 0.25,
    sigma_e: SigmaE = 1.0,
    seed: Seed = 0,
    prior: Prior = None,
    fix: Fix = None,
    workers: Workers = 2,
    out: Out = Path("vfinfer_output"),
    overwrite: Overwrite = False,
    model: Model = "fe",
    noise: Noise = "fixed",
    measure: Measure = None,
    force_reach: ForceReach = False,
    screen: Screen = None,
    prior_set: PriorSet = "paper",
    area_scale: AreaScale = None,
    uncalibrated: Uncalibrated = False,
    contact: Contact = "projection",
    contact_layer_mm: ContactLayer = 0.1,
    runs: Runs = 1,
) -> None:
    """Run an inference on this machine (in-process Dask LocalCluster); write the posterior, samples, figures and
    an HTML report (OUT/index.html); print the posterior table and what the data determined. The recording is
    first checked against the model's reach ('vfinfer reach')."""
    spec = build_spec(
        gaw,
        fps,
        sampler,
        n,
        particles,
        mesh,
        dt,
        duration,
        discard,
        sigma_e,
        seed,
        prior,
        fix,
        model=model,
        noise=noise,
        measure=measure,
        force_reach=force_reach,
        screen=screen,
        prior_set=prior_set,
        area_scale=parse_area_scale(area_scale, uncalibrated),
        contact=contact,
        contact_layer_mm=contact_layer_mm,
        runs=runs,
    )
    check_out(out, overwrite)
    reach_gate(spec, force_reach, workers)
    note_is(sampler)
    print_expected_cost(spec, workers)
    with staged_output(out) as stage:
        summary = run_local(spec, stage, workers)
    print_table(summary, title=f"Posterior for {gaw.name}")
    if summary.get("area_scale"):
        console.print(summary["area_scale"]["formatted"], highlight=False, soft_wrap=True)
    console.print(f"products written to {out}/; report: {out / 'index.html'}", highlight=False)


def _listen(host: str, port: int, family: int) -> socket.socket | None:
    """A listening socket on ``host:port`` (address ``family``), or None when it cannot be had. ``serve`` holds
    it from here on and hands it to uvicorn, so nothing the service starts before it serves (its LocalCluster
    binds random ports) can take the port in between."""
    try:
        s = socket.socket(family, socket.SOCK_STREAM)
    except OSError:
        return None
    try:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind((host, port))
        s.listen(2048)
        return s
    except OSError:
        s.close()
        return None


@app.command()
def serve(
    host: Annotated[str, typer.Option(help="address to listen on")] = "127.0.0.1",
    port: Annotated[
        int,
        typer.Option(min=0, max=65535, help="TCP port; 0: one the system picks, which the first line on stderr names"),
    ] = 8000,
    workers: Annotated[Optional[int], typer.Option(min=1, help="LocalCluster workers (if no scheduler)")] = None,
) -> None:
    """Run the HTTP API (with a LocalCluster unless VFINFER_SCHEDULER is set); API docs at /docs. The port is
    bound before anything else starts, and ``listening on http://HOST:PORT`` on stderr says which it is."""
    import uvicorn

    from .main import create_app
    from .settings import Settings

    if not host.strip():
        raise fail("--host is empty")
    try:
        family = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0][0]
    except OSError as exc:
        raise fail(f"--host {host!r}: {exc}") from None
    try:
        settings = Settings.from_env(**({"n_workers": workers} if workers else {}))
    except ValueError as exc:
        raise fail(f"settings from the environment: {exc}") from None
    sock = _listen(host, port, family)
    if sock is None:
        raise fail(f"cannot listen on {host}:{port}: the port is in use or not allowed")
    port = sock.getsockname()[1]  # the system's pick for --port 0
    typer.echo(f"listening on http://{host if ':' not in host else f'[{host}]'}:{port}", err=True)
    if not settings.users:
        warn("no tokens configured (VFINFER_TOKENS=user:token,...): every request will be 401")
    with sock:
        server = uvicorn.Server(uvicorn.Config(create_app(settings), host=host, port=port, log_level="info"))
        server.run(sockets=[sock])


@app.command()
def simulate(
    param: Annotated[
        Optional[list[str]],
        typer.Option(
            "--param",
            help="NAME=VALUE in paper units (E_body kPa, E_cover Pa, E_lig kPa, p_sub Pa, rho kg/m^3, "
            "eta Poise, x0 mm), repeatable; others keep the paper's Table 3 values",
        ),
    ] = None,
    mesh: Mesh = "medium",
    dt: Dt = 5e-5,
    duration: Duration = 0.55,
    discard: Discard = 0.25,
    contact: Contact = "projection",
    contact_layer_mm: ContactLayer = 0.1,
    fps: Annotated[float, typer.Option(parser=POSITIVE, help="frame rate of the GAW written, frames/s")] = 2000.0,
    out: Annotated[Path, typer.Option("--out", "-o", help="GAW CSV to write (time_s, area_mm2)")] = Path("gaw.csv"),
) -> None:
    """Run one forward simulation (Table 3 values unless overridden) and write its GAW as CSV."""
    from vfcore.config import SimConfig
    from vfcore.forward import simulate as sim
    from vfcore.params import TABLE3
    from vfvideo.io import write_gaw_csv

    values = parse_fixed(param, "--param")
    try:
        p = TABLE3.replace(**values)
    except ValueError as exc:
        raise fail(f"--param: {exc}") from None
    if not discard < duration:
        raise fail(f"--discard ({discard:g} s) must be shorter than --duration ({duration:g} s)")
    if fps * dt > 1.0:
        raise fail(f"--fps {fps:g} frames/s exceeds the simulation rate 1/dt = {1 / dt:.0f} steps/s")
    if out.is_dir():
        raise fail(f"--out {out} is a folder; give a file name such as gaw.csv")
    if not out.resolve().parent.is_dir():
        raise fail(f"--out {out}: the folder {out.resolve().parent} does not exist")
    try:
        r = sim(
            p,
            SimConfig(
                mesh=mesh,
                dt=dt,
                duration=duration,
                discard=discard,
                fps=fps,
                contact=contact,
                contact_layer_mm=contact_layer_mm,
            ),
        )
    except ValueError as exc:
        raise fail(f"simulation settings: {exc}") from None
    if not r.ok:
        raise fail(f"the simulation failed: {r.message}", code=1)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", dir=out.resolve().parent)
    os.close(fd)
    try:
        write_gaw_csv(
            tmp,
            r.t,
            r.gaw,
            r.fps,
            meta={
                "source": "vfinfer simulate",
                "params": json.dumps(p.as_dict()),
                "mesh": mesh,
                "dt": dt,
                "contact": contact,
            },
        )
        os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    if r.f0 == r.f0:
        console.print(
            f"f0={r.f0:.1f} Hz, {r.gaw.size} frames, peak area {r.gaw.max():.2f} mm^2 -> {out}", highlight=False
        )
    else:
        console.print(f"{r.gaw.size} frames, peak area {r.gaw.max():.2f} mm^2 -> {out}", highlight=False)
        warn(
            f"the fold does not oscillate at these parameters (no f0 after the {discard:g} s transient; p_sub = "
            f"{p.p_sub:g} Pa): the GAW written is not a phonation and cannot be fitted"
        )


@app.command()
def reach(
    mesh: Mesh = "coarse",
    dt: Dt = 5e-5,
    duration: Duration = 0.55,
    discard: Discard = 0.25,
    contact: Contact = "projection",
    contact_layer_mm: ContactLayer = 0.1,
    element: Element = "p1",
    prior: Prior = None,
    fix: Fix = None,
    prior_set: PriorSet = "paper",
    n: Annotated[int, typer.Option("--n", min=1, help="prior draws to simulate")] = 2000,
    seed: Annotated[int, typer.Option(min=0, help="random seed of the draws")] = 20190613,
    check: Annotated[Optional[Path], typer.Option(help="a GAW file to check against the reach")] = None,
    fps: Fps = None,
    rebuild: Annotated[bool, typer.Option(help="simulate anew even if an ensemble is cached")] = False,
) -> None:
    """Build (or show) the model's reach for a configuration and prior: the GAW measures of N prior draws
    (f0, peak area, open / speed / closing quotients; phonating fraction), cached for `vfinfer infer` and the
    service (folder: $VFINFER_CACHE_DIR/reach, else the user cache). With --check, compare a recording."""
    from vfcore.config import SimConfig
    from vfcore.inference import reach as rc
    from vfcore.inference.prior import PRIOR_SETS
    from vfcore.inference.prior import Prior as PriorBox

    bounds = {k: tuple(v) for k, v in PRIOR_SETS[prior_set].items()}
    bounds.update({k: tuple(v) for k, v in parse_priors(prior).items()})
    fixed = parse_fixed(fix)
    for k in fixed:
        bounds.pop(k, None)
    if not discard < duration:
        raise fail(f"--discard ({discard:g} s) must be shorter than --duration ({duration:g} s)")
    g = load_gaw(check, fps) if check is not None else None
    try:
        box = PriorBox(bounds, fixed)
        cfg = SimConfig(
            mesh=mesh,
            dt=dt,
            duration=duration,
            discard=discard,
            fps=min(4000.0, 1.0 / dt),
            contact=contact,
            contact_layer_mm=contact_layer_mm,
            element=element,
        )
    except ValueError as exc:
        raise fail(str(exc)) from None
    ens, exact = rc.find_ensemble(cfg, box)
    if rebuild or ens is None or not exact:
        t0 = time.perf_counter()

        console.print(f"reach: simulating {n} prior draws ({mesh} mesh, dt {dt:g} s, {duration:g} s)", highlight=False)
        with ProgressLines() as lines:

            def progress(done, total, el):
                lines.update("reach ensemble", done, total)
                if not lines.enabled:  # a terminal: a line a block, as ever
                    eta = el / done * (total - done) if done else 0.0
                    console.print(
                        f"reach: {done}/{total} draws simulated, {el:.0f} s elapsed, ~{eta:.0f} s left",
                        highlight=False,
                        soft_wrap=True,
                    )

            ens = rc.build_ensemble(cfg, box, n, seed, progress=progress)
        path = rc.save_cached(ens)
        console.print(f"reach: {ens.n} draws in {time.perf_counter() - t0:.0f} s -> {path}", highlight=False)
    else:
        console.print(f"reach: ensemble of {ens.n} draws from {ens.source}", highlight=False)
    console.print(rc.format_table(ens), highlight=False, soft_wrap=True)
    if g is not None:
        v = rc.check_reach(rc.recording_measures(g.area, g.fps), ens)
        console.print(f"{v.verdict}: {v.message}", highlight=False, soft_wrap=True)


@app.command()
def demo(
    out: Out = Path("demo_output"),
    particles: Annotated[int, typer.Option(min=10, help="SMC particles")] = 80,
    workers: Workers = 2,
    overwrite: Annotated[
        bool, typer.Option("--overwrite/--no-overwrite", help="replace the output of an earlier demo")
    ] = True,
) -> None:
    """End-to-end inference on the GAW shipped with the package (vfcore/data); writes table, figures and an HTML
    report (OUT/index.html)."""
    from vfcore.data import DEMO_GAW, DEMO_SMC, demo_spec_dict
    from worker.jobspec import JobSpec

    check_out(out, overwrite)
    if not DEMO_GAW.exists():
        try:
            from vfcore.data import make_demo_gaw

            console.print(f"{DEMO_GAW.name} missing: generating it with the FE model")
            make_demo_gaw()
        except ImportError as exc:
            raise fail(f"{DEMO_GAW} missing and the FE model is not available ({exc})", code=1) from None
    spec = JobSpec.model_validate(demo_spec_dict(sampler={**DEMO_SMC, "n_particles": particles}))
    console.print(
        f"demo: SMC with {particles} particles, ~{35 * particles} FE simulations ({spec.mesh} mesh, "
        f"dt={spec.dt} s) against {DEMO_GAW.name} (synthetic: the same model at Table 3 values + noise) "
        f"on {workers} local workers"
    )
    t0 = time.perf_counter()
    with staged_output(out) as stage:
        summary = run_local(spec, stage, workers, job_id="demo")
        _corner_with_truth(stage)
    print_table(summary, title="Posterior (demo GAW; truth: E_cover=636.2 Pa, p_sub=989.9 Pa)")
    _check_demo_truth(summary)
    console.print(f"wall time {time.perf_counter() - t0:.1f} s; products in {out}/")
    console.print(f"report: {(out / 'index.html').resolve()}", highlight=False, soft_wrap=True)


def _corner_with_truth(folder: Path) -> None:
    """Redraw the demo's pair plot with the values its GAW was made with (the job store does not know them)."""
    from vfcore.inference.posterior import Posterior
    from vfcore.params import TABLE3
    from worker.figures import fig_corner

    try:
        post = Posterior.from_netcdf(folder / "posterior.nc")
        (folder / "corner.png").write_bytes(fig_corner(post, truth={n: getattr(TABLE3, n) for n in post.names}))
    except Exception as exc:  # noqa: BLE001 - the plot without truth lines stays
        warn(f"pair plot with the truth not drawn: {type(exc).__name__}: {exc}")


def _check_demo_truth(summary: dict) -> None:
    """Say whether the 90% intervals cover the values the demo GAW was made with."""
    from vfcore.params import TABLE3

    for r in summary["table"]:
        truth = getattr(TABLE3, r["name"])
        inside = r["q05"] <= truth <= r["q95"]
        colour = "green" if inside else "yellow"
        console.print(
            f"[{colour}]{r['name']}: truth {truth:g} {'inside' if inside else 'OUTSIDE'} the 90% "
            f"interval [{r['q05']:.5g}, {r['q95']:.5g}][/{colour}]"
        )


from . import cli_client  # noqa: E402  (the service's client commands)
from .cli_diagnose import diagnose_cmd  # noqa: E402  (model diagnosis)
from .cli_gaw import gaw as _gaw  # noqa: E402  (video -> GAW)

app.command("gaw")(_gaw)
app.command("diagnose")(diagnose_cmd)
app.command("submit")(cli_client.submit)
app.command("list")(cli_client.list_jobs)
app.command("status")(cli_client.status)
app.command("cancel")(cli_client.cancel)
app.command("fetch")(cli_client.fetch)
app.command("diagnosis")(cli_client.diagnosis)
app.command("report")(cli_client.report)


def main() -> None:  # console-script entry point
    app()


if __name__ == "__main__":
    sys.exit(main())
