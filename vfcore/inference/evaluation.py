"""The per-draw results of a batch of forward evaluations, and how batches combine (concatenated, taken,
merged row by row). Every batch function of the samplers returns one."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass
class Evaluation:
    """Per-draw results of a batch of forward evaluations (k draws).

    ``loglik`` (k,) float64, ``-inf`` where the simulation failed; ``ok`` (k,) bool.
    The optional arrays are absent (None) for likelihoods that are not the FE model:
    ``gaw`` (k, n_compare) float32 aligned predictions (NaN rows for failures),
    ``mean_flow`` (k,) m^3/s; ``contact_impulse`` (k,) N s/m, the mean over cycles of the contact
    impulse per cycle and unit fold length, and ``contact_pressure_in_contact`` (k,) Pa, the mean
    pressure over the contact patch while in contact (see :class:`vfcore.result.CycleSummary`; these
    converge with the time step and mesh far better than the nodal peaks); ``mean_contact`` /
    ``max_contact`` (k,) Pa, the time-mean and maximum of the nodal peak contact pressure, which grow
    as the time step shrinks and change with the mesh (:ref:`model-contact`) and are kept for
    comparison with the paper's Table 7 only.
    ``extra`` (k, m) float64: per-draw summaries a likelihood adds (the integrated parameters'
    conditional means and sds of :class:`vfcore.diagnose.fit.ExtendedEvaluator`).
    ``messages``: one string per failed draw, ``"i: message"``.
    """

    loglik: np.ndarray
    ok: np.ndarray
    gaw: np.ndarray | None = None
    mean_flow: np.ndarray | None = None
    mean_contact: np.ndarray | None = None
    max_contact: np.ndarray | None = None
    extra: np.ndarray | None = None
    messages: tuple[str, ...] = ()
    contact_impulse: np.ndarray | None = None
    contact_pressure_in_contact: np.ndarray | None = None

    _ARRAYS = (
        "loglik",
        "ok",
        "gaw",
        "mean_flow",
        "mean_contact",
        "max_contact",
        "extra",
        "contact_impulse",
        "contact_pressure_in_contact",
    )

    def __len__(self) -> int:
        return int(self.loglik.shape[0])

    @property
    def n_failed(self) -> int:
        return int(np.count_nonzero(~self.ok))

    @classmethod
    def from_loglik(cls, loglik) -> Evaluation:
        ll = np.asarray(loglik, dtype=float).reshape(-1)
        ll = np.where(np.isnan(ll), -np.inf, ll)
        return cls(loglik=ll, ok=np.isfinite(ll))

    @classmethod
    def coerce(cls, x) -> Evaluation:
        """An Evaluation from an Evaluation or an array of log-likelihoods."""
        return x if isinstance(x, Evaluation) else cls.from_loglik(x)

    @classmethod
    def concat(cls, parts: Sequence[Evaluation]) -> Evaluation:
        parts = [cls.coerce(p) for p in parts]
        if not parts:
            return cls(loglik=np.empty(0), ok=np.empty(0, bool))
        kw = {}
        for name in cls._ARRAYS:
            vals = [getattr(p, name) for p in parts]
            kw[name] = None if any(v is None for v in vals) else np.concatenate(vals, axis=0)
        msgs, off = [], 0
        for p in parts:
            for m in p.messages:
                i, _, rest = m.partition(": ")
                msgs.append(f"{int(i) + off}: {rest}" if i.isdigit() else m)
            off += len(p)
        return cls(**kw, messages=tuple(msgs))

    def take(self, idx) -> Evaluation:
        idx = np.asarray(idx)
        kw = {n: (None if getattr(self, n) is None else getattr(self, n)[idx]) for n in self._ARRAYS}
        return Evaluation(**kw)

    def _combine(self, other: Evaluation, rows) -> Evaluation:
        """Per array, ``rows(mine, others)``; None where either side lacks the array."""
        kw = {}
        for n in self._ARRAYS:
            a, b = getattr(self, n), getattr(other, n)
            kw[n] = None if a is None or b is None else rows(a, b)
        return Evaluation(**kw)

    def where(self, mask, other: Evaluation) -> Evaluation:
        """Rows of ``other`` where ``mask`` else rows of ``self`` (same length)."""
        mask = np.asarray(mask, dtype=bool)
        return self._combine(
            other, lambda a, b: np.where(mask.reshape((-1,) + (1,) * (a.ndim - 1)), b, a).astype(a.dtype, copy=False)
        )

    def scatter(self, idx, other: Evaluation) -> Evaluation:
        """Copy of self with rows ``idx`` replaced by the rows of ``other``."""
        idx = np.asarray(idx)

        def put(a, b):
            a = a.copy()
            a[idx] = b
            return a

        return self._combine(other, put)
