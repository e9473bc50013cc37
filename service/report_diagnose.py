"""The HTML report of a diagnosis: one self-contained page (no script, no external host) that shows the
recording and the base fit, where the mismatch lies (residual by cycle phase, GAW measures the base fit
cannot reproduce), the physics named or the "no missing physics" verdict with its evidence (dlogZ, residual
RMS gain), the ranked catalogue entries (screening and refits), the before/after figure and the cost.

It renders the strict-JSON report that ``vfinfer diagnose`` writes (``diagnosis.json``) and the service
keeps (``<id>.diagnosis.json``): ``DiagnoseReport.to_dict()`` after ``jsonable``, so every number may be
``None``. The CLI links ``diagnosis.png`` relatively; the service embeds it as a data URI (a browser cannot
send the bearer token for an ``<img>``)."""

from __future__ import annotations

import json
import math
from html import escape
from pathlib import Path

from .report import data_section, fmt_num, html_table, page_head

#: The diagnosis figure, with its caption.
FIGURE_CAPTION = (
    "Top: the recording (dots), the base fit and, when physics is named, the extended fit, each with "
    "its 90 % band. Middle: the mean residual over the cycle (where the mismatch lies). Bottom: the "
    "GAW measures' posterior-predictive p-values of each fit."
)
#: Data files of a diagnosis output folder, with what each holds.
DATA_FILES = {
    "diagnosis.json": "the whole diagnosis (every number on this page, strict JSON)",
    "diagnosis.png": "the figure above",
}
_PHASES = ("closed", "opening", "peak", "closing")


def _num(x) -> float | None:
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) else None


def _pct(x) -> str:
    x = _num(x)
    return "–" if x is None else f"{100 * x:.0f} %"


def _p(p) -> str:
    p = _num(p)
    if p is None:
        return "–"
    return f"<strong>{p:.3f} *</strong>" if p < 0.05 else f"{p:.3f}"


def _duration(s) -> str:
    s = _num(s)
    if s is None:
        return "–"
    return f"{s:.1f} s" if s < 60 else f"{int(s) // 60} min {int(s) % 60:02d} s"


def _entry_info(name: str) -> tuple[str, str]:
    """The catalogue's kind and signature of an entry; blank where the catalogue does not know it (a report
    kept from an older catalogue still renders)."""
    try:
        from vfcore.diagnose.extensions import CATALOGUE
    except Exception:  # noqa: BLE001 - the page needs no catalogue, it only explains entries with it
        return "", ""
    e = CATALOGUE.get(name)
    return (e.kind, e.signature) if e is not None else ("", "")


def _verdict(d: dict) -> str:
    verdict = escape(str(d.get("verdict") or "no verdict"))
    win = d.get("winner")
    fc = d.get("fit_check") or {}
    if fc and fc.get("fits") is False:
        return (
            f"<div class='warn'><strong>The model does not fit.</strong> {verdict}.</div><p class='muted'>The "
            f"best fit leaves {fmt_num(_num(fc.get('ratio')), '.1f')} times the recording's noise (at most "
            f"{fmt_num(_num(fc.get('max_ratio')), 'g')} counts as a fit): no catalogue entry explains the "
            "recording, so none is named; the ranked entries below are partial explanations.</p>"
        )
    mat = d.get("material") or {}
    if not win and mat.get("found"):
        return (
            f"<div class='ok'><strong>The fixed parameters were wrong.</strong><br>{verdict}.</div>"
            "<p class='muted'>Freeing the material parameters held at Table 3 explains the mismatch by the "
            "naming rule; no catalogued extension then beat the freed base model.</p>"
        )
    if not win:
        return (
            f"<div class='warn'><strong>{verdict}</strong>: no catalogued extension beat the base model by "
            "the naming rule (a log-evidence gain well above its error, a residual RMS at least 30 % lower, "
            "not at its null value). The ranked entries below say how close each came.</div>"
        )
    row = next((r for r in d.get("ranking") or [] if r.get("name") == win), {})
    a = (d.get("refits") or {}).get(win) or {}
    phys = d.get("physics") or win
    gain = a.get("rms_improvement", row.get("rms_gain"))
    loc = d.get("local") or {}
    ev = (
        (
            f"named on the local comparison: dlogZ = {fmt_num(_num(loc.get('dlogZ')), '.2f')} ± "
            f"{fmt_num(_num(loc.get('se')), '.2f')} nats against the base model refitted in its material mode; "
            if loc
            else ""
        )
        + f"dlogZ = {fmt_num(_num(row.get('delta')), '.2f')} ± {fmt_num(_num(row.get('delta_se')), '.2f')} nats against "
        f"{escape(str(d.get('reference') or 'base'))}; residual RMS {fmt_num(_num((d.get('base') or {}).get('residual_rms')), '.3g')}"
        f" → {fmt_num(_num(a.get('residual_rms')), '.3g')} mm² ({_pct(gain)} lower)"
    )
    if _num(row.get("residual_removed")) is not None:
        ev += f"; removes {_pct(row['residual_removed'])} of the localised residual"
    rivals = d.get("rivals") or []
    riv = (
        (
            "<p>The evidence cannot tell it from: "
            + ", ".join(
                f"{escape(str(r.get('physics')))} ({fmt_num(_num(r.get('gap')), '.1f')} ± {fmt_num(_num(r.get('se')), '.1f')} nats below)"
                for r in rivals
            )
            + ".</p>"
        )
        if rivals
        else ""
    )
    model = f" (entry <code>{escape(win)}</code>)" if phys != win else ""
    return (
        f"<div class='ok'><strong>Missing physics: {escape(str(phys))}</strong>{model}<br>{ev}.</div>{riv}"
        f"<p class='muted'>{verdict}</p>"
    )


def _material(m: dict) -> str:
    """The pinned base fit against the one with the held parameters freed (vfcore.diagnose.material)."""
    held = ", ".join(f"{escape(str(k))} (held at {fmt_num(_num(v), 'g')})" for k, v in (m.get("held_at") or {}).items())
    rows = [
        [
            label,
            f"{fmt_num(_num(f.get('log_evidence')), '.2f')} ± {fmt_num(_num(f.get('log_evidence_se')), '.2f')}",
            fmt_num(_num(f.get("residual_rms")), ".3g"),
        ]
        for label, f in (("held at Table 3", m.get("pinned") or {}), ("freed", m.get("free") or {}))
    ]
    free = (m.get("free") or {}).get("params") or {}
    est = html_table(
        ["freed parameter", "posterior mean", "sd"],
        [
            [
                escape(str(k)),
                fmt_num(_num((free.get(k) or {}).get("mean")), ".4g"),
                fmt_num(_num((free.get(k) or {}).get("sd")), ".3g"),
            ]
            for k in (m.get("held_at") or {})
        ],
    )
    outcome = "explains the mismatch" if m.get("found") else f"does not explain it ({escape(str(m.get('reason')))})"
    return (
        f"<p>The base model held {held}. Freeing them (the scale anchored by {escape(str(m.get('anchor')))}) "
        f"{outcome}: dlogZ = {fmt_num(_num(m.get('delta')), '.2f')} ± {fmt_num(_num(m.get('delta_se')), '.2f')}, "
        f"residual RMS {_pct(m.get('rms_gain'))} lower; the {escape(str(m.get('kept')))} model is the base of "
        "everything below.</p>" + html_table(["base model", "log evidence", "residual RMS (mm²)"], rows) + est
    )


def _mismatch(b: dict, d: dict) -> str:
    parts = []
    dom = b.get("dominant_phase")
    where = (
        f"concentrated in the <strong>{escape(str(dom))}</strong> phase"
        if dom in _PHASES
        else "spread over the whole cycle"
    )
    parts.append(f"<p>The base fit's residual (RMS {fmt_num(_num(b.get('residual_rms')), '.3g')} mm²) is {where}.</p>")
    prms, conc = b.get("phase_rms") or {}, b.get("concentration") or {}
    if prms:
        rows = [
            [
                escape(p) + (" ◀" if p == dom else ""),
                fmt_num(_num(prms.get(p)), ".3g"),
                fmt_num(_num(conc.get(p)), ".2f"),
            ]
            for p in _PHASES
            if p in prms
        ]
        parts.append(
            html_table(["cycle phase", "residual RMS (mm²)", "concentration (> 1: more than its share)"], rows)
        )
    meas = b.get("measures") or {}
    if meas:
        win = d.get("winner")
        a = (d.get("refits") or {}).get(win) if win else None
        head = ["GAW measure", "recording", "base predicts", "base p"]
        if a:
            head += [f"{win} predicts", f"{win} p"]
        rows, off = [], []
        pv = b.get("pvalues") or {}
        for k, m in meas.items():
            m = m or {}
            row = [
                escape(k.replace("_", " ")),
                fmt_num(_num(m.get("observed"))),
                fmt_num(_num(m.get("predicted"))),
                _p(pv.get(k)),
            ]
            if a:
                am = (a.get("measures") or {}).get(k) or {}
                row += [fmt_num(_num(am.get("predicted"))), _p((a.get("pvalues") or {}).get(k))]
            rows.append(row)
            if (_num(pv.get(k)) or 1.0) < 0.05:
                off.append(k.replace("_", " "))
        noise = fmt_num(_num(b.get("predictive_noise_sd")), ".3g")
        said = (
            f"The base fit cannot reproduce: <strong>{escape(', '.join(off))}</strong>."
            if off
            else "Every measure of the recording lies within what the base fit's replicated recordings show."
        )
        parts.append(
            f"<p>{said}</p>"
            + html_table(head, rows)
            + f"<p class='muted'>Two-sided posterior-predictive p-values (* p &lt; 0.05); replicated "
            f"recordings carry noise sd {noise} mm², estimated from the recording.</p>"
        )
    return "".join(parts)


def _entries(d: dict) -> str:
    """Every catalogue entry the diagnosis looked at, best first: refitted ones by dlogZ, then those only
    screened by their screening score."""
    ranking = {r.get("name"): r for r in d.get("ranking") or [] if r.get("name")}
    refits = d.get("refits") or {}
    screening = {k: v for k, v in (d.get("screening") or {}).items() if not k.startswith("_") and isinstance(v, dict)}
    names = sorted(set(ranking) | set(refits), key=lambda n: -(_num((ranking.get(n) or {}).get("delta")) or -1e300))
    names += sorted(
        (n for n in screening if n not in names), key=lambda n: -(_num(screening[n].get("score")) or -1e300)
    )
    if not names:
        return "<p>No catalogue entry was screened.</p>"
    rows = []
    for i, n in enumerate(names, 1):
        r, a, s = ranking.get(n) or {}, refits.get(n) or {}, screening.get(n) or {}
        kind, sig = _entry_info(n)
        ext = {k: v for k, v in (a.get("params") or {}).items() if isinstance(v, dict)}
        ext_names = set(s.get("best_phi") or {})
        try:
            from vfcore.diagnose.extensions import get

            ext_names |= set(get(n).param_names)
        except Exception:  # noqa: BLE001 - without the catalogue, all of the refit's parameters are shown
            ext_names |= set(ext)
        pars = (
            ", ".join(
                f"{escape(k)} = {fmt_num(_num(v.get('mean')))} ± {fmt_num(_num(v.get('sd')), '.2g')}"
                for k, v in ext.items()
                if k in ext_names
            )
            or "–"
        )
        if n in ranking:
            found = "<strong>named</strong>" if n == d.get("winner") else ("yes" if r.get("found") else "no")
            why = escape(str(r.get("reason") or ""))
        else:
            found, why = "not refitted", ""
        rows.append(
            [
                str(i),
                f"<code>{escape(n)}</code>" + (f"<br><span class='muted'>{escape(sig)}</span>" if sig else ""),
                escape(kind),
                fmt_num(_num(s.get("score")), ".2f"),
                f"{fmt_num(_num(r.get('delta')), '.2f')} ± {fmt_num(_num(r.get('delta_se')), '.2f')}" if r else "–",
                fmt_num(_num(a.get("residual_rms")), ".3g"),
                _pct(a.get("rms_improvement")),
                pars,
                found + (f"<br><span class='muted'>{why}</span>" if why else ""),
            ]
        )
    return html_table(
        [
            "#",
            "entry",
            "kind",
            "screening score (nats)",
            "dlogZ (nats)",
            "residual RMS (mm²)",
            "RMS gain",
            "extension parameters",
            "found",
        ],
        rows,
        numeric_from=3,
    )


def _cost(d: dict) -> str:
    n = _num(d.get("n_simulations"))
    sims = f"{int(n):,} simulations, wall time" if n is not None else "Wall time"
    parts = [f"<p>{sims} {_duration(d.get('wall_s'))}.</p>"]
    by = (d.get("cost") or {}).get("by_stage") or {}
    if by:
        rows = [
            [escape(k), _duration((v or {}).get("wall_s")), fmt_num(_num((v or {}).get("simulations")), ",.0f")]
            for k, v in sorted(by.items(), key=lambda kv: -(_num((kv[1] or {}).get("wall_s")) or 0))
        ]
        parts.append(html_table(["stage", "wall time", "simulations"], rows))
    rs = d.get("resume_store") or {}
    if _num(rs.get("earlier_attempts")):
        parts.append(
            f"<p class='muted'>Resumed after {int(rs['earlier_attempts'])} interrupted attempt(s): "
            f"{int(_num(rs.get('parts_read')) or 0):,} stored simulation batches read back; the wall time "
            "includes the earlier attempts.</p>"
        )
    return "".join(parts)


def render_diagnosis_report(
    d: dict, figure: str | None, title: str, links: dict[str, str] | None = None, source: dict | None = None
) -> str:
    """The page of a diagnosis report ``d``. ``figure``: ``src`` of the diagnosis figure (a relative file name
    or a data URI), or None; ``links``: data file name -> ``href``; ``source``: label -> value lines about
    the recording and the settings (file, job, estimated parameters...), shown as given (escaped here)."""
    b = d.get("base") or {}
    parts = [page_head(title), f"<h1>{escape(title)}</h1>", "<h2>Verdict</h2>", _verdict(d)]
    src = dict(source or {})
    req = d.get("request") or {}
    for k in ("candidates", "n_particles", "refit_particles", "refit_start", "max_refits", "continuation", "seed"):
        if k in req:
            src.setdefault(k.replace("_", " "), req[k] if req[k] is not None else "all")
    parts.append("<h2>Recording and base fit</h2>")
    if src:
        parts.append(
            html_table(
                ["", ""],
                [
                    [escape(str(k)), escape(", ".join(map(str, v)) if isinstance(v, list) else str(v))]
                    for k, v in src.items()
                ],
                numeric_from=9,
            )
        )
    parts.append(
        html_table(
            ["residual RMS (mm²)", "log evidence", "simulations"],
            [
                [
                    fmt_num(_num(b.get("residual_rms")), ".3g"),
                    f"{fmt_num(_num(b.get('log_evidence')), '.2f')} ± {fmt_num(_num(b.get('log_evidence_se')), '.2f')}",
                    fmt_num(_num(b.get("n_simulations")), ",.0f"),
                ]
            ],
            numeric_from=0,
        )
    )
    bp = {k: v for k, v in (b.get("params") or {}).items() if isinstance(v, dict)}
    if bp:
        parts.append(
            html_table(
                ["base parameter", "mean", "sd"],
                [
                    [escape(k), fmt_num(_num(v.get("mean")), ".5g"), fmt_num(_num(v.get("sd")), ".3g")]
                    for k, v in bp.items()
                ],
            )
        )
    if figure:
        parts.append(
            f"<figure><img src='{escape(figure)}' alt='recording, base and extended fits, residual by "
            f"phase and measure p-values'><figcaption>{FIGURE_CAPTION}</figcaption></figure>"
        )
    if d.get("material"):
        parts.append("<h2>Material first</h2>" + _material(d["material"]))
    parts.append("<h2>Where the mismatch lies</h2>" + _mismatch(b, d))
    parts.append(
        "<h2>Catalogue entries, ranked</h2><p class='muted'>Screening: the best log-likelihood gain of "
        "the entry with the material parameters held at the base posterior. Refit: base plus extension "
        "fitted by SMC; dlogZ is its log-evidence gain over the reference, with its error.</p>" + _entries(d)
    )
    raised = d.get("warnings") or []  # Python warnings the run raised, as the command line showed them
    if raised:
        parts.append("<h2>Warnings</h2>" + "".join(f"<div class='warn'>{escape(str(w))}</div>" for w in raised))
    notes = d.get("notes") or []
    if notes:
        parts.append("<h2>Notes</h2>" + "".join(f"<div class='warn'>{escape(str(n))}</div>" for n in notes))
    parts.append("<h2>Cost</h2>" + _cost(d))
    if links:
        parts.append(data_section(links, DATA_FILES))
    parts.append("</body></html>")
    return "\n".join(parts)


def write_diagnosis_report(
    folder: Path, d: dict | None = None, title: str = "vfinfer diagnosis", source: dict | None = None
) -> Path:
    """``folder/index.html`` for a diagnosis output folder: ``d`` (default: ``folder/diagnosis.json``), the
    figure and the data files that exist there, linked relatively so the folder can be moved or zipped."""
    folder = Path(folder)
    if d is None:
        d = json.loads((folder / "diagnosis.json").read_text())
    fig = "diagnosis.png" if (folder / "diagnosis.png").exists() else None
    links = {n: n for n in DATA_FILES if (folder / n).exists()}
    path = folder / "index.html"
    path.write_text(render_diagnosis_report(d, fig, title, links, source), encoding="utf-8")
    return path
