"""The HTML report of a finished job: one self-contained page (no script, no external host) that shows
the fit, the posterior table with units and 90 % intervals, the pair plot, flow and contact pressure,
the sampler's diagnostics in plain words and the run's cost.

The CLI writes it as ``index.html`` beside the figures (linked relatively, so the folder can be moved or
zipped); the service serves it with the figures embedded as data URIs (a browser cannot send the bearer
token for an ``<img>``)."""

from __future__ import annotations

import base64
import json
import math
from html import escape
from pathlib import Path

from vfcore.config import contact_label
from worker.reduce import convergence_note

#: Figures of a job, in the order shown, with their captions.
FIGURES = {
    "gaw_fit": "The recording (dots) and the fit: the model's 90 % posterior band and the wider band of "
    "replicated recordings (model plus observation noise).",
    "corner": "Posterior pair plot (paper units); lines mark the posterior mean and, where known, the truth.",
    "contact_pressure": "Posterior predictive flow rate and contact pressure.",
}
#: Data files of an output folder, with what each holds.
DATA_FILES = {
    "samples.csv": "every weighted draw: parameters (paper units), log_weight, weight, n_resampled (plain CSV)",
    "samples.json": "metadata of samples.csv: names, units, method, ESS, evidence, warnings",
    "posterior.nc": "ArviZ InferenceData (NetCDF-4): posterior, weighted samples, observed GAW, posterior predictive",
    "posterior.json": "the full summary (all numbers on this page)",
}

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:2em auto;max-width:1100px;
padding:0 1em;color:#222;line-height:1.4}
h1{font-size:1.5em;margin-bottom:.2em}h2{font-size:1.15em;margin-top:1.6em;border-bottom:1px solid #ddd}
table{border-collapse:collapse;margin:.5em 0;font-size:.92em}th,td{padding:.25em .7em;border-bottom:1px solid #eee}
th{text-align:left;background:#f6f6f6}td.n{text-align:right;font-variant-numeric:tabular-nums}
.warn{background:#fff6e0;border-left:4px solid #e0a000;padding:.4em .8em;margin:.4em 0}
.ok{background:#eef8ee;border-left:4px solid #3a3;padding:.4em .8em;margin:.4em 0}
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #eee}figcaption{font-size:.9em;color:#555}
.muted{color:#666;font-size:.9em}
code{background:#f3f3f3;padding:0 .25em}pre{background:#f3f3f3;padding:.6em;overflow-x:auto}
"""

#: Headers of every HTML page the service serves: the page may load nothing from anywhere (its images are
#: data URIs, its style inline) and run no script; a signed link in the address bar is never sent on as a
#: referrer nor kept in a cache.
PAGE_HEADERS = {
    "Content-Security-Policy": "default-src 'none'; img-src data:; style-src 'unsafe-inline'; base-uri 'none'; "
    "form-action 'none'; frame-ancestors 'none'",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
    "X-Content-Type-Options": "nosniff",
}


def fmt_num(x, fmt: str = ".4g") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    return format(x, fmt)


def _diagnostics(s: dict) -> list[tuple[str, str]]:
    """The sampler's diagnostics, each with a sentence saying what it means."""
    out = []
    n = s.get("n_samples") or 0
    ess = s.get("ess")
    if ess is not None:
        good = ess >= min(100.0, 0.1 * n) if n else ess >= 100
        out.append(
            (
                "ok" if good else "warn",
                f"Effective sample size {ess:.1f} of {n} weighted draws: "
                + (
                    "enough for the table's intervals."
                    if good
                    else "few independent draws; the intervals are rough (more particles or draws help)."
                ),
            )
        )
    k = s.get("pareto_k")
    if k is not None:
        out.append(
            (
                "ok" if k < 0.7 else "warn",
                f"Pareto k̂ = {k:.2f}: "
                + (
                    "the importance weights are reliable (k̂ < 0.7)."
                    if k < 0.7
                    else "the importance weights are unreliable (k̂ ≥ 0.7)."
                ),
            )
        )
    le, se = s.get("log_evidence"), s.get("log_evidence_se")
    if le is not None:
        out.append(
            ("ok", f"Log evidence {le:.2f} ± {fmt_num(se, '.2f')} (compares models fitted to the same recording).")
        )
    info = s.get("info") or {}
    runs = info.get("runs")
    if runs and len(runs) > 1:
        kept = [r for r in runs if r.get("kept")]
        key, what = (
            ("log_evidence", "log evidence")
            if info.get("run_rule") == "evidence"
            else ("best_loglik", "best log-likelihood")
        )
        out.append(
            (
                "ok" if len(kept) == len(runs) else "warn",
                f"{len(runs)} independent SMC runs, {what} "
                + ", ".join(f"{r[key]:.1f}" + ("" if r.get("kept") else " (left out)") for r in runs)
                + (
                    ": every run reached the same to within the gap, and they share the posterior equally."
                    if len(kept) == len(runs)
                    else f": {len(runs) - len(kept)} settled more than {fmt_num(info.get('run_gap'), 'g')} nats below "
                    "the best and are left out; a single run could have reported that basin, and a sampler that "
                    "missed a basin once may have missed one in the runs kept, so the intervals are not "
                    "calibrated."
                ),
            )
        )
    nc = s.get("noise_check")
    if nc and nc.get("residual_rms"):
        r = nc["residual_rms"]
        out.append(
            (
                "ok",
                f"Residual RMS of the fit {fmt_num(r.get('q50'), '.3g')} mm² (90 %: {fmt_num(r.get('q05'), '.3g')} – "
                f"{fmt_num(r.get('q95'), '.3g')}); noise model: {escape(str(nc.get('noise')))}, "
                f"σ_e = {fmt_num(nc.get('sigma_e'), '.3g')} mm².",
            )
        )
    return out


def html_table(head: list[str], rows: list[list[str]], numeric_from: int = 1) -> str:
    h = "".join(f"<th>{escape(c)}</th>" for c in head)
    body = "".join(
        "<tr>"
        + "".join(f"<td class='n'>{c}</td>" if i >= numeric_from else f"<td>{c}</td>" for i, c in enumerate(r))
        + "</tr>"
        for r in rows
    )
    return f"<table><tr>{h}</tr>{body}</table>"


def page_head(title: str) -> str:
    return (
        f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>{escape(title)}</title>"
        f"<meta name='viewport' content='width=device-width, initial-scale=1'><style>{_CSS}</style></head><body>"
    )


def html_page(title: str, body: str) -> str:
    """A page in the report's style: ``title`` (escaped here) as its heading, then ``body`` (HTML, escaped by
    the caller)."""
    return f"{page_head(title)}\n<h1>{escape(title)}</h1>\n{body}\n</body></html>"


def render_report(
    summary: dict, images: dict[str, str], title: str, links: dict[str, str] | None = None, timings: dict | None = None
) -> str:
    """The report page. ``images``: figure name -> ``src`` (a relative file name or a data URI); ``links``:
    data file name -> ``href``; ``timings``: the run's cost (``timings.json`` of a local run, or the job's
    status timings)."""
    s = summary
    parts = [
        page_head(title),
        f"<h1>{escape(title)}</h1>",
        f"<p class='muted'>{escape(str(s.get('method', '?')).upper())} posterior from "
        f"{s.get('n_simulations', '?')} simulations ({s.get('n_failed', 0)} failed); "
        f"{s.get('n_samples', '?')} weighted draws, {s.get('n_resampled', '?')} resampled.</p>",
    ]
    m = s.get("model")
    if m and m.get("name", "fe") == "fe":
        parts.append(
            f"<p class='muted'>Model: {escape(str(m.get('mesh')))} mesh, dt {fmt_num(m.get('dt'), 'g')} s, "
            f"{fmt_num(m.get('duration'), 'g')} s simulated ({fmt_num(m.get('discard'), 'g')} s discarded), "
            f"contact {escape(contact_label(m.get('contact'), m.get('contact_layer_mm')))}.</p>"
        )
    warnings = s.get("warnings") or []
    if warnings:
        parts.append("<h2>Warnings</h2>" + "".join(f"<div class='warn'>{escape(w)}</div>" for w in warnings))
    if "gaw_fit" in images:
        parts.append(
            f"<h2>Recording and fit</h2><figure><img src='{escape(images['gaw_fit'])}' alt='GAW fit'>"
            f"<figcaption>{FIGURES['gaw_fit']}</figcaption></figure>"
        )
    rows = [
        [
            escape(r["name"]),
            escape(r.get("unit", "")),
            fmt_num(r["mean"], ".5g"),
            fmt_num(r["sd"], ".4g"),
            fmt_num(r.get("pct"), ".1f"),
            f"{fmt_num(r['q05'], '.5g')} – {fmt_num(r['q95'], '.5g')}",
        ]
        for r in s.get("table", [])
    ]
    parts.append(
        "<h2>Posterior</h2>"
        + html_table(["parameter", "unit", "mean", "sd", "sd, % of mean", "90 % interval"], rows, numeric_from=2)
    )
    if "corner" in images:
        parts.append(
            f"<figure><img src='{escape(images['corner'])}' alt='posterior pair plot'>"
            f"<figcaption>{FIGURES['corner']}</figcaption></figure>"
        )
    pred = s.get("predictive") or {}
    if pred:
        rows = [
            [
                escape(k.replace("_", " ")),
                escape(q.get("unit", "")),
                fmt_num(q.get("mean")),
                fmt_num(q.get("sd"), ".3g"),
                f"{fmt_num(q.get('q05'))} – {fmt_num(q.get('q95'))}" + escape(convergence_note(q)),
            ]
            for k, q in pred.items()
        ]
        parts.append(
            "<h2>Flow and contact pressure</h2>"
            + html_table(["quantity", "unit", "mean", "sd", "90 % interval"], rows, numeric_from=2)
        )
    if "contact_pressure" in images:
        parts.append(
            f"<figure><img src='{escape(images['contact_pressure'])}' alt='flow and contact pressure'>"
            f"<figcaption>{FIGURES['contact_pressure']}</figcaption></figure>"
        )
    ident = s.get("identifiability") or {}
    combos = ident.get("combinations") or []
    if combos:
        rows = [
            [
                escape(c["label"]),
                escape(c.get("unit", "")),
                fmt_num(c.get("value"), ".5g"),
                f"{fmt_num(c.get('q05'))} – {fmt_num(c.get('q95'))}",
                fmt_num(c.get("ratio"), ".2f"),
            ]
            for c in combos
        ]
        parts.append(
            "<h2>What a GAW determines</h2><p class='muted'>A GAW cannot fix the common scale of the "
            "stiffnesses, pressure, density and viscosity; these combinations are unchanged by it "
            "(ratio: posterior sd / prior sd of the log, 0 = fully determined, 1 = only the prior).</p>"
            + html_table(["combination", "unit", "value", "90 % interval", "ratio"], rows, numeric_from=2)
        )
    diag = _diagnostics(s)
    if diag:
        parts.append("<h2>Sampler diagnostics</h2>" + "".join(f"<div class='{c}'>{t}</div>" for c, t in diag))
    if timings:
        cost = ", ".join(
            f"{escape(k[:-2].replace('_', ' '))} {fmt_num(v, '.1f')} s"
            if k.endswith("_s")
            else f"{escape(k.replace('_', ' '))} {fmt_num(v, ',.0f')}"
            for k, v in timings.items()
            if isinstance(v, (int, float)) and not isinstance(v, bool)
        )
        parts.append(f"<h2>Cost</h2><p>{cost}</p>")
    if links:
        parts.append(data_section(links, DATA_FILES))
    parts.append("</body></html>")
    return "\n".join(parts)


def data_section(links: dict, described: dict) -> str:
    """The page's "Data" list: each ``{name: href}`` linked, with its description from ``described``."""
    return (
        "<h2>Data</h2><ul>"
        + "".join(
            f"<li><a href='{escape(href)}'>{escape(name)}</a>: {escape(described.get(name, ''))}</li>"
            for name, href in links.items()
        )
        + "</ul>"
    )


def write_report(folder: Path, summary: dict, title: str = "vfinfer result") -> Path:
    """``folder/index.html`` for an output folder: figures and data files that exist there, linked relatively."""
    folder = Path(folder)
    images = {n: f"{n}.png" for n in FIGURES if (folder / f"{n}.png").exists()}
    links = {n: n for n in DATA_FILES if (folder / n).exists() or n == "posterior.json"}
    timings = None
    if (folder / "timings.json").exists():
        try:
            timings = json.loads((folder / "timings.json").read_text())
        except ValueError:
            timings = None
    path = folder / "index.html"
    path.write_text(render_report(summary, images, title, links, timings), encoding="utf-8")
    return path


def data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")
