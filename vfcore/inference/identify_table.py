"""The identifiability table (:mod:`.identify` computes it): its data object, JSON form and plain text.

:func:`format_identifiability` reads the JSON form (:meth:`Identifiability.to_dict`), so a stored job
summary's entry renders the same as a fresh table; :mod:`.identify` re-exports both names.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field

from ..strict_json import jsonable

__all__ = ["Identifiability", "format_identifiability"]


@dataclass
class Identifiability:
    """The identifiability table of one posterior (module docstring); ``to_dict`` is JSON-able."""

    parameters: list[dict]
    principal: list[dict]
    scale: dict | None
    combinations: list[dict]
    anchors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    log_names: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return jsonable(asdict(self))

    def format(self) -> str:
        return format_identifiability(self.to_dict())


def format_identifiability(d: Mapping) -> str:
    """Plain-text rendering of :meth:`Identifiability.to_dict` (also of a stored job summary's entry)."""

    def f(x, fmt=".4g"):
        return "-" if x is None else format(x, fmt)

    lines = [
        "identifiability: posterior sd / prior sd (1 = the data said nothing, 0 = fully determined)",
        f"{'parameter':<9} {'unit':<7} {'mean':>11} {'sd':>10} {'prior sd':>10} {'sd/prior':>8}",
    ]
    for r in d.get("parameters", []):
        lines.append(
            f"{r['name']:<9} {r['unit']:<7} {f(r['mean'], '11.5g')} {f(r['sd'], '10.4g')} "
            f"{f(r['prior_sd'], '10.4g')} {f(r['ratio'], '8.3f')}"
        )
    names = d.get("log_names", [])
    if d.get("principal"):
        lines.append("principal directions of the posterior in log coordinates, least narrowed first:")
        lines.append("  " + f"{'sd':>8} {'prior sd':>8} {'ratio':>6}  " + " ".join(f"{n:>7}" for n in names))
        for r in d["principal"]:
            lines.append(
                "  "
                + f"{f(r['sd'], '8.3g')} {f(r['prior_sd'], '8.3g')} {f(r['ratio'], '6.3f')}  "
                + " ".join(f"{r['loadings'].get(n, 0.0):7.3f}" for n in names)
            )
    s = d.get("scale")
    if s:
        lines.append(
            f"common scale of {', '.join(s['names'])}: posterior sd {f(s['posterior_sd'], '.3g')} "
            f"(log units), prior sd {f(s['prior_sd'], '.3g')} (ratio {f(s['ratio'], '.2f')}), "
            f"the box along the ray {f(s['ray_prior_sd'], '.3g')} (ratio {f(s['ray_ratio'], '.2f')}); "
            f"sd of the common factor {f(s['log_c_sd'], '.3g')} in log"
            + ("; exact symmetry, not anchored" if s.get("exact_symmetry") else "")
        )
    if d.get("combinations"):
        lines.append("scale-invariant combinations (SI units): geometric mean, sd of the log, prior sd of the log:")
        for c in d["combinations"]:
            lines.append(
                f"  {c['label']:<20} {f(c['value'], '11.5g')} {c['unit']:<8} sd(log) {f(c['log_sd'], '.3g')} "
                f"prior {f(c['prior_log_sd'], '.3g')} ratio {f(c['ratio'], '.3f')} "
                f"(90%: {f(c['q05'], '.4g')} .. {f(c['q95'], '.4g')})"
            )
    if d.get("anchors"):
        lines.append("anchors of the scale: " + "; ".join(d["anchors"]))
    lines += [f"WARNING: {w}" for w in d.get("warnings", [])]
    return "\n".join(lines)
