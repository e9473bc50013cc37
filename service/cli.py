"""``vfinfer`` command line: local inference, the service, a client for it, and the demo."""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.table import Table

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Bayesian inference of vocal-fold properties from glottal area waveforms.")
console = Console()



# ------------------------------------------------------------------------------------ helpers
def _kv(items: list[str] | None, what: str) -> dict[str, str]:
    out = {}
    for it in items or []:
        k, sep, v = it.partition("=")
        if not sep:
            raise typer.BadParameter(f"{what} must look like NAME=VALUE, got {it!r}")
        out[k.strip()] = v.strip()
    return out


def _fail(msg: str) -> typer.Exit:
    console.print(f"[red]error:[/red] {msg}", highlight=False, soft_wrap=True)   # one line, however long
    return typer.Exit(2)


def reach_gate(spec, force_reach: bool) -> None:
    """The reach check before any sampling (docs/inference.md, "The model's reach"): a recording outside the
    reach of the model and prior exits 2 with one ``error:`` line unless ``force_reach`` (then a warning);
    a marginal or unchecked one gets a warning; an inside one a one-line note."""
    try:
        v = spec.reach()
    except ValueError as exc:
        raise _fail(f"reach check: {exc}") from None
    if v.verdict == "outside" and not force_reach:
        raise _fail(v.message + "; --force-reach fits anyway")
    w = v.warning("--force-reach")
    if w is None:
        console.print(f"reach: {v.message}", highlight=False, soft_wrap=True)
    elif spec.model == "fe":                      # the toy test double has no reach to check
        console.print(f"[yellow]WARNING[/yellow] {w}", highlight=False, soft_wrap=True)


def parse_measurements(items: list[str] | None) -> dict[str, list[float]]:
    """``--measure NAME=MEAN:SD`` (paper units, repeatable) -> ``{name: [mean, sd]}``; bad input raises
    ``typer.Exit(2)`` after one ``error:`` line (the values are checked by
    :func:`vfcore.inference.problem.validate_measurements`, as in a job spec)."""
    from vfcore.inference.problem import validate_measurements
    out: dict[str, list[float]] = {}
    for it in items or []:
        name, sep, rest = it.partition("=")
        name = name.strip()
        mean_s, sep2, sd_s = rest.partition(":")
        if not sep or not sep2:
            raise _fail(f"--measure must look like NAME=MEAN:SD (paper units, e.g. p_sub=1000:50), got {it!r}")
        if name in out:
            raise _fail(f"--measure {name} given twice")
        try:
            out[name] = [float(mean_s), float(sd_s)]
        except ValueError:
            raise _fail(f"--measure {name}: MEAN and SD must be numbers, got {rest!r}") from None
    try:
        validate_measurements(out)
    except ValueError as exc:
        raise _fail(f"--measure: {exc}") from None
    return out


def build_spec(gaw: Path, fps: float | None, sampler: str, n: int, particles: int, mesh: str, dt: float,
               duration: float, discard: float, sigma_e: float, seed: int, prior: list[str] | None,
               fix: list[str] | None, chunk_size: int | None = None, model: str = "fe", noise: str = "fixed",
               measure: list[str] | None = None, force_reach: bool = False):
    """A validated JobSpec from CLI options (exit code 2 with the pydantic message on bad input)."""
    from pydantic import ValidationError

    from vfvideo.io import read_gaw
    from worker.jobspec import JobSpec

    if sampler not in ("is", "smc"):
        raise _fail(f"--sampler must be 'smc' or 'is', got {sampler!r}")
    measurements = parse_measurements(measure)
    g = read_gaw(gaw, fps=fps)
    priors = {}
    for k, v in _kv(prior, "--prior").items():
        lo, _, hi = v.partition(":")
        priors[k] = [float(lo), float(hi)]
    fixed = {k: float(v) for k, v in _kv(fix, "--fix").items()}
    smp = {"kind": "is", "n_samples": n} if sampler == "is" else {"kind": "smc", "n_particles": particles}
    body = {"model": model, "gaw": {"areas": [float(a) for a in g.area], "fps": float(g.fps), "units": "mm2"},
            "priors": priors or None, "fixed": fixed, "sampler": smp, "mesh": mesh, "dt": dt,
            "duration": duration, "discard": discard, "sigma_e": sigma_e, "noise": noise, "seed": seed,
            "chunk_size": chunk_size, "measurements": measurements, "force_reach": bool(force_reach)}
    try:
        return JobSpec.model_validate(body)
    except ValidationError as exc:
        for e in exc.errors():
            console.print(f"[red]error:[/red] invalid {'.'.join(map(str, e['loc'])) or 'input'}: {e['msg']}",
                          highlight=False)
        raise typer.Exit(2) from None


def print_table(summary: dict, title: str = "Posterior") -> None:
    """The posterior in the layout of Hadwin et al. (2019), Table 3: estimate, sd and sd as % of it."""
    t = Table(title=title)
    for col in ("parameter", "unit", "estimate", "sd", "% of est.", "5%", "95%"):
        t.add_column(col, justify="left" if col in ("parameter", "unit") else "right")
    for r in summary["table"]:
        t.add_row(r["name"], r["unit"], f"{r['mean']:.5g}", f"{r['sd']:.4g}", f"{r['pct']:.2f}" if r["pct"] else "-",
                  f"{r['q05']:.5g}", f"{r['q95']:.5g}")
    console.print(t)
    le, se = summary.get("log_evidence"), summary.get("log_evidence_se")
    console.print(f"method={summary['method']}  simulations={summary['n_simulations']} "
                  f"(failed {summary['n_failed']})  ESS={summary['ess']:.1f}  "
                  f"log evidence={le if le is None else round(le, 3)} +- {se if se is None else round(se, 3)}")
    for name, q in (summary.get("predictive") or {}).items():
        console.print(f"  {name}: {q['mean']:.4g} +- {q['sd']:.3g} {q['unit']} (90%: {q['q05']:.4g} .. {q['q95']:.4g})")
    print_identifiability(summary.get("identifiability"))
    for w in summary.get("warnings", []):
        console.print(f"[yellow]WARNING[/yellow] {w}")


def print_identifiability(d: dict | None) -> None:
    """The identifiability table of a posterior summary (vfcore.inference.identify): what the data
    determined (posterior sd / prior sd), the common scale, and the combinations a GAW determines."""
    if not d:
        return
    if d.get("error"):
        console.print(f"[yellow]identifiability table not available:[/yellow] {d['error']}", highlight=False)
        return

    def f(x, fmt):
        return "-" if x is None else format(x, fmt)
    t = Table(title="What the data determined (posterior sd / prior sd: 1 = only the prior, 0 = fully determined)")
    for col in ("parameter", "unit", "estimate", "sd", "prior sd", "sd / prior sd"):
        t.add_column(col, justify="left" if col in ("parameter", "unit") else "right")
    for r in d.get("parameters", []):
        t.add_row(r["name"], r["unit"], f(r["mean"], ".5g"), f(r["sd"], ".4g"), f(r["prior_sd"], ".4g"),
                  f(r["ratio"], ".3f"))
    console.print(t)
    names = d.get("log_names", [])
    if d.get("principal"):
        t = Table(title="Principal directions of the posterior (log coordinates), least narrowed first")
        for col in ("sd", "prior sd", "ratio", *names):
            t.add_column(col, justify="right")
        for r in d["principal"]:
            t.add_row(f(r["sd"], ".3g"), f(r["prior_sd"], ".3g"), f(r["ratio"], ".3f"),
                      *(f(r["loadings"].get(n, 0.0), ".2f") for n in names))
        console.print(t)
    s = d.get("scale")
    if s:
        console.print(f"common scale of {', '.join(s['names'])}: posterior sd {f(s['posterior_sd'], '.3g')} in log, "
                      f"{f(s['ray_ratio'], '.0%')} of what the prior box allows along it "
                      f"(prior sd {f(s['prior_sd'], '.3g')}); the common factor's sd in log: {f(s['log_c_sd'], '.3g')}",
                      highlight=False)
    if d.get("combinations"):
        t = Table(title="Combinations a GAW determines (unchanged by the common scale; SI units)")
        for col in ("combination", "unit", "value", "sd of log", "prior sd of log", "ratio", "5%", "95%"):
            t.add_column(col, justify="left" if col in ("combination", "unit") else "right")
        for c in d["combinations"]:
            t.add_row(c["label"], c["unit"], f(c["value"], ".5g"), f(c["log_sd"], ".3g"), f(c["prior_log_sd"], ".3g"),
                      f(c["ratio"], ".3f"), f(c["q05"], ".4g"), f(c["q95"], ".4g"))
        console.print(t)
    if d.get("anchors"):
        console.print("scale anchored by: " + "; ".join(d["anchors"]), highlight=False)


def export_products(store_path: Path, out: Path) -> dict:
    """Copy summary, samples CSV and figures out of a job store into ``out``."""
    from worker import store as st
    out.mkdir(parents=True, exist_ok=True)
    summary = st.read_summary(store_path)
    (out / "posterior.json").write_text(json.dumps(summary, indent=1, sort_keys=True))
    (out / "posterior_table.txt").write_text(summary.get("formatted", "") + "\n")
    ident = summary.get("identifiability")
    if ident and not ident.get("error"):
        from vfcore.inference.identify import format_identifiability
        (out / "identifiability.txt").write_text(format_identifiability(ident) + "\n")
    for name in st.PRODUCT_NAMES:
        blob = st.read_blob(store_path, name)
        if blob is not None:
            (out / (("samples.csv") if name == "samples_csv" else f"{name}.png")).write_bytes(blob)
    return summary


def run_local(spec, out: Path, workers: int, job_id: str = "local") -> dict:
    """Run a job on an in-process LocalCluster with a progress bar; products go to ``out``."""
    from distributed import Client, LocalCluster
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from worker.run import register_warm_up, run_job

    out.mkdir(parents=True, exist_ok=True)
    store_path = out / f"{job_id}.zarr"
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None) as cl, \
            Client(cl) as client, Progress(TextColumn("{task.description}"), BarColumn(),
                                           TextColumn("{task.completed}/{task.total} sims  {task.fields[ess]}"),
                                           TimeElapsedColumn(), console=console) as bar:
        register_warm_up(client)
        task = bar.add_task("simulating", total=spec.n_simulations, ess="")

        def report(p):
            bar.update(task, completed=p.n_done, total=max(p.n_total, p.n_done), description=p.phase,
                       ess=f"ESS={p.ess:.1f}" if p.ess == p.ess else "")

        stats = run_job(client, job_id, store_path, spec, report=report)
    summary = export_products(store_path, out)
    (out / "timings.json").write_text(json.dumps(stats, indent=1))
    return summary


def _http(url: str, token: str | None):
    import httpx
    token = token or os.environ.get("VFINFER_TOKEN")
    if not token:
        console.print("[red]no token: pass --token or set VFINFER_TOKEN[/red]")
        raise typer.Exit(2)
    return httpx.Client(base_url=url, headers={"Authorization": f"Bearer {token}"}, timeout=60)


def _check(r) -> dict:
    if r.status_code >= 400:
        console.print(f"[red]HTTP {r.status_code}[/red] {r.text[:2000]}")
        raise typer.Exit(1)
    return r.json()


# ------------------------------------------------------------------------------------ options
Fps = Annotated[Optional[float], typer.Option(help="frame rate, if the file does not say")]
Sampler = Annotated[str, typer.Option(help="'smc' (adaptive, tempered SMC) or 'is' (importance sampling from the "
                                             "prior, the paper's method)")]
N = Annotated[int, typer.Option("--n", help="IS: number of prior draws")]
Particles = Annotated[int, typer.Option(help="SMC: number of particles")]
Mesh = Annotated[str, typer.Option(help="coarse | medium | fine")]
Prior = Annotated[Optional[list[str]], typer.Option("--prior", help="NAME=LO:HI (paper units), repeatable")]
Fix = Annotated[Optional[list[str]], typer.Option("--fix", help="NAME=VALUE (paper units), repeatable")]
Url = Annotated[str, typer.Option(envvar="VFINFER_URL", help="service URL")]
Token = Annotated[Optional[str], typer.Option(envvar="VFINFER_TOKEN", help="bearer token")]
Model = Annotated[str, typer.Option(hidden=True, help="'fe' or the 'toy' test double (tests only)")]
Noise = Annotated[str, typer.Option(help="'fixed': the likelihood uses --sigma-e (paper, Eq. 15); 'marginal': the "
                                         "noise sd is unknown and integrated out (log-uniform, 0.01-100 mm^2)")]
ForceReach = Annotated[bool, typer.Option(
    "--force-reach", help="fit even when the recording lies outside the model's reach (its f0 or peak area beyond "
                          "every prior-predictive draw); without it such a recording exits 2 before sampling")]
Measure = Annotated[Optional[list[str]], typer.Option(
    "--measure", help="NAME=MEAN:SD (paper units), repeatable: a Gaussian measurement of an estimated parameter, "
                      "e.g. p_sub=1000:50; anchors the common scale a GAW cannot determine")]


def _note_is(sampler: str) -> None:
    if sampler == "is":
        console.print("note: importance sampling from the prior is the paper's method; beyond one or two free "
                      "parameters its effective sample size collapses (the run warns when it does); the default "
                      "--sampler smc needs far fewer simulations", highlight=False)


# ------------------------------------------------------------------------------------ commands
@app.command()
def infer(gaw: Path, fps: Fps = None, sampler: Sampler = "smc", n: N = 2000, particles: Particles = 200,
          mesh: Mesh = "coarse", dt: float = 5e-5, duration: float = 0.55, discard: float = 0.25,
          sigma_e: float = 1.0, seed: int = 0, prior: Prior = None, fix: Fix = None,
          workers: Annotated[int, typer.Option(help="local worker processes")] = 2,
          out: Annotated[Path, typer.Option(help="output folder")] = Path("vfinfer_output"),
          model: Model = "fe", noise: Noise = "fixed", measure: Measure = None,
          force_reach: ForceReach = False) -> None:
    """Run an inference on this machine (in-process Dask LocalCluster) and print the posterior table
    and what the data determined (the identifiability table). The recording is first checked against
    the model's reach (``vfinfer reach``)."""
    spec = build_spec(gaw, fps, sampler, n, particles, mesh, dt, duration, discard, sigma_e, seed, prior, fix,
                      model=model, noise=noise, measure=measure, force_reach=force_reach)
    reach_gate(spec, force_reach)
    _note_is(sampler)
    summary = run_local(spec, out, workers)
    print_table(summary, title=f"Posterior for {gaw.name}")
    console.print(f"products written to {out}/")


@app.command()
def serve(host: str = "127.0.0.1", port: int = 8000,
          workers: Annotated[Optional[int], typer.Option(help="LocalCluster workers (if no scheduler)")] = None
          ) -> None:
    """Run the HTTP API (with a LocalCluster unless VFINFER_SCHEDULER is set)."""
    import uvicorn

    from .main import create_app
    from .settings import Settings
    settings = Settings.from_env(**({"n_workers": workers} if workers else {}))
    if not settings.users:
        console.print("[yellow]no tokens configured (VFINFER_TOKENS=user:token,...): every request will be 401[/yellow]")
    uvicorn.run(create_app(settings), host=host, port=port, log_level="info")


@app.command()
def submit(gaw: Path, url: Url = "http://127.0.0.1:8000", token: Token = None, fps: Fps = None,
           sampler: Sampler = "smc", n: N = 2000, particles: Particles = 200, mesh: Mesh = "coarse",
           dt: float = 5e-5, duration: float = 0.55, discard: float = 0.25, sigma_e: float = 1.0, seed: int = 0,
           prior: Prior = None, fix: Fix = None, model: Model = "fe", noise: Noise = "fixed",
           measure: Measure = None, force_reach: ForceReach = False) -> None:
    """Submit a job to a running service; prints the job id (and the service's warnings)."""
    spec = build_spec(gaw, fps, sampler, n, particles, mesh, dt, duration, discard, sigma_e, seed, prior, fix,
                      model=model, noise=noise, measure=measure, force_reach=force_reach)
    _note_is(sampler)
    with _http(url, token) as http:
        d = _check(http.post("/jobs", content=spec.to_json(), headers={"Content-Type": "application/json"}))
    for w in d.get("warnings", []):
        console.print(f"[yellow]WARNING[/yellow] {w}", highlight=False, soft_wrap=True)
    console.print(d["id"])


@app.command()
def status(job_id: str, url: Url = "http://127.0.0.1:8000", token: Token = None,
           wait: Annotated[bool, typer.Option(help="poll until the job finishes")] = False) -> None:
    """Show a job's state and progress."""
    with _http(url, token) as http:
        while True:
            d = _check(http.get(f"/jobs/{job_id}"))
            p = d["progress"]
            console.print(f"{d['id']}  {d['state']:<9} {p['simulations_done']}/{p['simulations_total']} sims  "
                          f"ESS={d['ess']}")
            if not wait or d["state"] in ("done", "failed", "cancelled"):
                break
            time.sleep(2)
    if d.get("error"):
        console.print(f"[red]{d['error']}[/red]")


@app.command()
def fetch(job_id: str, url: Url = "http://127.0.0.1:8000", token: Token = None,
          out: Annotated[Path, typer.Option(help="output folder")] = Path("vfinfer_output")) -> None:
    """Download a finished job's posterior, samples and figures; print the table."""
    out.mkdir(parents=True, exist_ok=True)
    with _http(url, token) as http:
        summary = _check(http.get(f"/jobs/{job_id}/posterior"))
        (out / "posterior.json").write_text(json.dumps(summary, indent=1, sort_keys=True))
        r = http.get(f"/jobs/{job_id}/samples")
        if r.status_code == 200:
            (out / "samples.csv").write_bytes(r.content)
        for name in ("gaw_fit", "corner", "contact_pressure"):
            r = http.get(f"/jobs/{job_id}/figures/{name}")
            if r.status_code == 200:
                (out / f"{name}.png").write_bytes(r.content)
    print_table(summary, title=f"Posterior of job {job_id}")


@app.command()
def simulate(param: Annotated[Optional[list[str]], typer.Option("--param", help="NAME=VALUE, repeatable")] = None,
             mesh: Mesh = "medium", dt: float = 5e-5, duration: float = 0.55, discard: float = 0.25,
             fps: float = 2000.0, out: Annotated[Path, typer.Option(help="GAW CSV to write")] = Path("gaw.csv")
             ) -> None:
    """Run one forward simulation (Table 3 values unless overridden) and write its GAW as CSV."""
    from vfcore.config import SimConfig
    from vfcore.params import TABLE3
    from vfcore.forward import simulate as sim
    from vfvideo.io import write_gaw_csv

    p = TABLE3.replace(**{k: float(v) for k, v in _kv(param, "--param").items()})
    r = sim(p, SimConfig(mesh=mesh, dt=dt, duration=duration, discard=discard, fps=fps))
    if not r.ok:
        console.print(f"[red]simulation failed:[/red] {r.message}")
        raise typer.Exit(1)
    write_gaw_csv(out, r.t, r.gaw, r.fps, meta={"source": "vfinfer simulate", "params": json.dumps(p.as_dict()),
                                                "mesh": mesh, "dt": dt})
    console.print(f"f0={r.f0:.1f} Hz, {r.gaw.size} frames, peak area {r.gaw.max():.2f} mm^2 -> {out}")


@app.command()
def reach(mesh: Mesh = "coarse", dt: float = 5e-5, duration: float = 0.55, discard: float = 0.25,
          prior: Prior = None, fix: Fix = None,
          n: Annotated[int, typer.Option("--n", help="prior draws to simulate")] = 2000,
          seed: Annotated[int, typer.Option(help="random seed of the draws")] = 20190613,
          check: Annotated[Optional[Path], typer.Option(help="a GAW file to check against the reach")] = None,
          fps: Fps = None,
          rebuild: Annotated[bool, typer.Option(help="simulate anew even if an ensemble is cached")] = False) -> None:
    """Build (or show) the model's reach for a configuration and prior: the GAW measures of N prior draws
    (f0, peak area, open / speed / closing quotients; phonating fraction), cached for `vfinfer infer` and the
    service (folder: $VFINFER_CACHE_DIR/reach, else the user cache). With --check, compare a recording."""
    from vfcore.config import SimConfig
    from vfcore.inference import reach as rc
    from vfcore.inference.prior import TABLE2_BOUNDS
    from vfcore.inference.prior import Prior as PriorBox

    try:
        bounds = {k: tuple(v) for k, v in TABLE2_BOUNDS.items()}
        for k, v in _kv(prior, "--prior").items():
            lo, _, hi = v.partition(":")
            bounds[k] = (float(lo), float(hi))
        fixed = {k: float(v) for k, v in _kv(fix, "--fix").items()}
        for k in fixed:
            bounds.pop(k, None)
        box = PriorBox(bounds, fixed)
        cfg = SimConfig(mesh=mesh, dt=dt, duration=duration, discard=discard, fps=min(4000.0, 1.0 / dt))
    except (ValueError, typer.BadParameter) as exc:
        raise _fail(str(exc)) from None
    if n < 1:
        raise _fail(f"--n must be >= 1, got {n}")
    ens, exact = rc.find_ensemble(cfg, box)
    if rebuild or ens is None or not exact:
        t0 = time.perf_counter()

        def progress(done, total, el):
            eta = el / done * (total - done) if done else 0.0
            console.print(f"reach: {done}/{total} draws simulated, {el:.0f} s elapsed, ~{eta:.0f} s left",
                          highlight=False, soft_wrap=True)
        console.print(f"reach: simulating {n} prior draws ({mesh} mesh, dt {dt:g} s, {duration:g} s)", highlight=False)
        ens = rc.build_ensemble(cfg, box, n, seed, progress=progress)
        path = rc.save_cached(ens)
        console.print(f"reach: {ens.n} draws in {time.perf_counter() - t0:.0f} s -> {path}", highlight=False)
    else:
        console.print(f"reach: ensemble of {ens.n} draws from {ens.source}", highlight=False)
    console.print(rc.format_table(ens), highlight=False, soft_wrap=True)
    if check is not None:
        from vfvideo.io import read_gaw
        g = read_gaw(check, fps=fps)
        v = rc.check_reach(rc.recording_measures(g.area, g.fps), ens)
        console.print(f"{v.verdict}: {v.message}", highlight=False, soft_wrap=True)


@app.command()
def demo(out: Annotated[Path, typer.Option(help="output folder")] = Path("demo_output"),
         particles: Annotated[int, typer.Option(help="SMC particles")] = 80,
         workers: int = 2) -> None:
    """End-to-end inference on the GAW shipped with the package (vfcore/data); writes table and figures."""
    from vfcore.data import DEMO_GAW, DEMO_SMC, DEMO_TRUTH, demo_spec_dict
    from worker.jobspec import JobSpec

    if not DEMO_GAW.exists():
        try:
            from vfcore.data import make_demo_gaw
            console.print(f"{DEMO_GAW.name} missing: generating it with the FE model")
            make_demo_gaw()
        except ImportError as exc:
            console.print(f"[red]{DEMO_GAW} missing and the FE model is not available ({exc})[/red]")
            raise typer.Exit(1) from None
    spec = JobSpec.model_validate(demo_spec_dict(sampler={**DEMO_SMC, "n_particles": particles}))
    console.print(f"demo: SMC with {particles} particles, ~{35 * particles} FE simulations ({spec.mesh} mesh, "
                  f"dt={spec.dt} s) against "
                  f"{DEMO_GAW.name} (synthetic: the same model at Table 3 values + noise) "
                  f"on {workers} local workers")
    t0 = time.perf_counter()
    summary = run_local(spec, out, workers, job_id="demo")
    print_table(summary, title="Posterior (demo GAW; truth: E_cover=636.2 Pa, p_sub=989.9 Pa)")
    _check_demo_truth(summary)
    console.print(f"wall time {time.perf_counter() - t0:.1f} s; products in {out}/")


from .cli_gaw import gaw as _gaw  # noqa: E402  (video -> GAW lives in its own module)

app.command("gaw")(_gaw)

from .cli_diagnose import diagnose_cmd as _diagnose  # noqa: E402  (model diagnosis)

app.command("diagnose")(_diagnose)


@app.command("diagnosis")
def diagnosis(job_id: str, url: Url = "http://127.0.0.1:8000", token: Token = None,
              start: Annotated[bool, typer.Option(help="start a diagnosis of the finished job (POST)")] = False,
              candidates: Annotated[Optional[str], typer.Option(help="with --start: comma-separated catalogue "
                                                                     "entries (default: all implemented)")] = None,
              particles: Annotated[Optional[int], typer.Option(help="with --start: SMC particles of each base fit")] = None,
              refit_particles: Annotated[Optional[int], typer.Option(help="with --start: particles of each refit")] = None,
              max_refits: Annotated[Optional[int], typer.Option(help="with --start: most observation-level refits")] = None,
              continuation: Annotated[Optional[bool], typer.Option(
                  "--continuation/--no-continuation", help="with --start: the window-continuation search")] = None,
              seed: Annotated[Optional[int], typer.Option(help="with --start: random seed")] = None,
              wait: Annotated[bool, typer.Option(help="poll, printing each new stage, until it ends")] = False,
              cancel: Annotated[bool, typer.Option(help="cancel the running diagnosis (DELETE)")] = False,
              out: Annotated[Optional[Path], typer.Option(help="when done: write diagnosis.json and "
                                                               "diagnosis.png here and print the report")] = None,
              ) -> None:
    """A job's diagnosis on a running service: start it, follow it, cancel it, fetch it
    (POST/GET/DELETE /jobs/{id}/diagnosis; the same pipeline as ``vfinfer diagnose``)."""
    from .cli_diagnose import print_report, stage_line
    if start and cancel:
        console.print("[red]error:[/red] --start and --cancel exclude each other")
        raise typer.Exit(2)
    body = {k: v for k, v in (("n_particles", particles), ("refit_particles", refit_particles),
                              ("max_refits", max_refits), ("continuation", continuation), ("seed", seed)) if v is not None}
    if candidates:
        body["candidates"] = [c.strip() for c in candidates.split(",") if c.strip()]
    if body and not start:
        console.print("[red]error:[/red] diagnosis settings need --start")
        raise typer.Exit(2)
    with _http(url, token) as http:
        if start:
            _check(http.post(f"/jobs/{job_id}/diagnose", json=body or None))
            console.print(f"diagnosis of {job_id} started")
        if cancel:
            _check(http.delete(f"/jobs/{job_id}/diagnosis"))
            console.print(f"diagnosis of {job_id} cancelling")
        last = None
        while True:
            d = _check(http.get(f"/jobs/{job_id}/diagnosis"))
            p = d.get("progress")
            if p and (p["stage"], p.get("entry")) != last:
                last = (p["stage"], p.get("entry"))
                console.print(stage_line(p), highlight=False)
            if not wait or d["state"] != "running":
                break
            time.sleep(2)
        console.print(f"{job_id}  diagnosis {d['state']}")
        if d.get("error"):
            console.print(f"[red]{d['error']}[/red]", highlight=False)
        if d["state"] == "done" and out is not None:
            out.mkdir(parents=True, exist_ok=True)
            (out / "diagnosis.json").write_text(json.dumps(d["report"], indent=1))
            r = http.get(f"/jobs/{job_id}/diagnosis/figure")
            if r.status_code == 200:
                (out / "diagnosis.png").write_bytes(r.content)
            print_report(d["report"])
            console.print(f"wrote {out / 'diagnosis.json'}" + (" and diagnosis.png" if r.status_code == 200 else ""))
    if d["state"] == "failed":
        raise typer.Exit(1)


def _check_demo_truth(summary: dict) -> None:
    """Say whether the 90% intervals cover the values the demo GAW was made with."""
    from vfcore.params import TABLE3
    for r in summary["table"]:
        truth = getattr(TABLE3, r["name"])
        inside = r["q05"] <= truth <= r["q95"]
        colour = "green" if inside else "yellow"
        console.print(f"[{colour}]{r['name']}: truth {truth:g} {'inside' if inside else 'OUTSIDE'} the 90% "
                      f"interval [{r['q05']:.5g}, {r['q95']:.5g}][/{colour}]")


def main() -> None:  # console-script entry point
    app()


if __name__ == "__main__":
    sys.exit(main())
