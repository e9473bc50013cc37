"""Rich tables of a posterior summary: the posterior in the layout of the paper's Table 3, the predictive
summaries, and the identifiability table (what the data determined)."""

from __future__ import annotations

from rich.console import Console
from rich.table import Table

from .cli_common import warn

console = Console()


def print_table(summary: dict, title: str = "Posterior") -> None:
    """The posterior in the layout of Hadwin et al. (2019), Table 3: estimate, sd and sd as % of it."""
    t = Table(title=title)
    for col in ("parameter", "unit", "estimate", "sd", "% of est.", "5%", "95%"):
        t.add_column(col, justify="left" if col in ("parameter", "unit") else "right")
    for r in summary["table"]:
        t.add_row(
            r["name"],
            r["unit"],
            f"{r['mean']:.5g}",
            f"{r['sd']:.4g}",
            f"{r['pct']:.2f}" if r["pct"] else "-",
            f"{r['q05']:.5g}",
            f"{r['q95']:.5g}",
        )
    console.print(t)
    le, se = summary.get("log_evidence"), summary.get("log_evidence_se")
    console.print(
        f"method={summary['method']}  simulations={summary['n_simulations']} "
        f"(failed {summary['n_failed']})  ESS={summary['ess']:.1f}  "
        f"log evidence={le if le is None else round(le, 3)} +- {se if se is None else round(se, 3)}"
    )
    from worker.reduce import convergence_note

    for name, q in (summary.get("predictive") or {}).items():
        console.print(
            f"  {name}: {q['mean']:.4g} +- {q['sd']:.3g} {q['unit']} (90%: {q['q05']:.4g} .. {q['q95']:.4g})"
            f"{convergence_note(q)}",
            highlight=False,
            soft_wrap=True,
        )
    print_identifiability(summary.get("identifiability"))
    for w in summary.get("warnings", []):
        warn(w)


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
        t.add_row(
            r["name"], r["unit"], f(r["mean"], ".5g"), f(r["sd"], ".4g"), f(r["prior_sd"], ".4g"), f(r["ratio"], ".3f")
        )
    console.print(t)
    names = d.get("log_names", [])
    if d.get("principal"):
        t = Table(title="Principal directions of the posterior (log coordinates), least narrowed first")
        for col in ("sd", "prior sd", "ratio", *names):
            t.add_column(col, justify="right")
        for r in d["principal"]:
            t.add_row(
                f(r["sd"], ".3g"),
                f(r["prior_sd"], ".3g"),
                f(r["ratio"], ".3f"),
                *(f(r["loadings"].get(n, 0.0), ".2f") for n in names),
            )
        console.print(t)
    s = d.get("scale")
    if s:
        console.print(
            f"common scale of {', '.join(s['names'])}: posterior sd {f(s['posterior_sd'], '.3g')} in log, "
            f"{f(s['ray_ratio'], '.0%')} of what the prior box allows along it "
            f"(prior sd {f(s['prior_sd'], '.3g')}); the common factor's sd in log: {f(s['log_c_sd'], '.3g')}",
            highlight=False,
        )
    if d.get("combinations"):
        t = Table(title="Combinations a GAW determines (unchanged by the common scale; SI units)")
        for col in ("combination", "unit", "value", "sd of log", "prior sd of log", "ratio", "5%", "95%"):
            t.add_column(col, justify="left" if col in ("combination", "unit") else "right")
        for c in d["combinations"]:
            t.add_row(
                c["label"],
                c["unit"],
                f(c["value"], ".5g"),
                f(c["log_sd"], ".3g"),
                f(c["prior_log_sd"], ".3g"),
                f(c["ratio"], ".3f"),
                f(c["q05"], ".4g"),
                f(c["q95"], ".4g"),
            )
        console.print(t)
    if d.get("anchors"):
        console.print("scale anchored by: " + "; ".join(d["anchors"]), highlight=False)
