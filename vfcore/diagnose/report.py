"""The diagnosis report: the fits, their summaries, the ranking and the verdict, with the fit check
(:mod:`.adequacy`) that decides whether the best fit explains the recording at all."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from ..inference.posterior import Posterior
from .adequacy import check_fit
from .material import material_sentence
from .rank import NO_FINDING, RankReport
from .state import DiagnosisState, Run

__all__ = ["DiagnoseReport", "finish"]


@dataclass
class DiagnoseReport:
    base: Posterior
    before: dict
    screening: dict
    refits: dict[str, Posterior]
    after: dict[str, dict]
    ranking: RankReport
    n_simulations: int
    wall_s: float
    notes: list[str] = field(default_factory=list)
    #: wall time and rows evaluated per stage and per entry (:meth:`.progress.ProgressTracker.cost`)
    cost: dict = field(default_factory=dict)
    #: freeing the material combinations held at Table 3 (:func:`material_first`), None when none were
    material: dict | None = None
    #: whether the best fit explains the recording (:func:`.adequacy.check_fit`), None when not checked
    fit_check: object | None = None

    @property
    def fits(self) -> bool:
        return self.fit_check is None or self.fit_check.fits

    @property
    def verdict(self) -> str:
        if not self.fits:
            partial = (
                self.ranking.verdict.removeprefix("missing physics: ")
                if self.ranking.winner
                else (material_sentence(self.material) if self.material and self.material["found"] else None)
            )
            return self.fit_check.sentence(partial)
        if self.material and self.material["found"]:
            m = material_sentence(self.material)
            return (
                f"{self.ranking.verdict}; and {m}"
                if self.ranking.winner
                else f"the fixed parameters were wrong: {m}; {NO_FINDING}"
            )
        return self.ranking.verdict

    @property
    def winner(self) -> str | None:
        return self.ranking.winner if self.fits else None

    def to_dict(self) -> dict:
        rows = self.ranking.table()
        return {
            "verdict": self.verdict,
            "winner": self.winner,
            "physics": self.ranking.physics if self.fits else None,
            "material": self.material,
            "fit_check": None if self.fit_check is None else self.fit_check.to_dict(),
            "rivals": [{"physics": f, "gap": g, "se": e} for f, g, e in self.ranking.rivals],
            "base": self.before,
            "screening": {
                k: {
                    kk: (vv if not isinstance(vv, dict) else {a: float(b) for a, b in vv.items()})
                    for kk, vv in v.items()
                }
                for k, v in self.screening.items()
            },
            "refits": self.after,
            "ranking": rows,
            "reference": self.ranking.reference,
            "local": (
                None
                if self.winner is None or self.ranking.local is None
                else {"dlogZ": self.ranking.local[0], "se": self.ranking.local[1]}
            ),
            "n_simulations": self.n_simulations,
            "wall_s": self.wall_s,
            "notes": self.notes,
            "cost": self.cost,
        }


def finish(run: Run, st: DiagnosisState, ranking: RankReport) -> DiagnoseReport:
    """The report of a diagnosis, with its fit check over the base and every refit not at its null
    value; the last stage of every way through :func:`vfcore.diagnose.diagnose`."""
    checked = None
    after = st.after
    if run.options.max_rms_ratio is not None:
        checked = check_fit(
            {"base": st.before, **{n: after[n] for n in after if not after[n].get("null_consistent")}},
            run.options.max_rms_ratio,
        )
    run.track.at("done")
    return DiagnoseReport(
        base=st.base,
        before=st.before,
        screening=st.screening,
        refits=st.refits,
        after=after,
        ranking=ranking,
        n_simulations=st.n_simulations,
        wall_s=time.perf_counter() - run.t0,
        notes=st.notes,
        cost=run.track.cost(),
        material=st.material,
        fit_check=checked,
    )
