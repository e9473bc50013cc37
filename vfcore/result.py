"""Result of one forward simulation."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .config import SimConfig
from .params import Params

#: Oversampling of ``SimResult.gaw_hr`` relative to the camera rate.
HR_OVERSAMPLE = 10


@dataclass(frozen=True)
class CycleSummary:
    """Per-cycle summaries over the kept (post-transient) window.

    All arrays have shape (n_cycles,). Pressures in Pa, areas in mm^2, flow in m^3/s. A cycle runs
    from one upward crossing of the mid-range area to the next, so each closed phase lies inside one
    cycle.

    Contact (:ref:`model-contact`; every quantity per unit fold length, from the per-step
    contact forces f_j(t_k) >= 0 of the surface nodes, N/m, step h):

    * ``contact_impulse`` (N s/m): h * sum_k sum_j f_j(t_k) over the cycle's steps, the normal
      momentum the midline takes from the fold per cycle.
    * ``contact_duration`` (s): h * number of steps with any node in contact.
    * ``contact_pressure_in_contact`` (Pa): the impulse divided by the space-time extent of the
      contact, h * sum_k (sum of the edge shares of the nodes in contact at t_k) (m s): the mean
      pressure over the contact patch while in contact; 0 for a cycle without contact.
    * ``max_contact_pressure_unconverged`` / ``mean_peak_contact_pressure_unconverged`` (Pa): the
      nodal contact pressure (force / edge share) at its maximum over the cycle, and the cycle's
      time-mean of its spatial maximum. Both depend on the time step and the mesh (the impact
      force scales like m v / h) and are kept for comparison only.
    """

    t_start: np.ndarray  # s, cycle start (glottal-area minimum) relative to the kept window
    period: np.ndarray  # s
    peak_area: np.ndarray  # mm^2
    min_area: np.ndarray  # mm^2
    mean_flow: np.ndarray  # m^3/s
    mean_peak_contact_pressure_unconverged: np.ndarray  # Pa, time-mean over the cycle of the spatial max
    max_contact_pressure_unconverged: np.ndarray  # Pa, max over the cycle and over nodes
    contact_impulse: np.ndarray = field(default_factory=lambda: np.empty(0))  # N s/m
    contact_duration: np.ndarray = field(default_factory=lambda: np.empty(0))  # s
    contact_pressure_in_contact: np.ndarray = field(default_factory=lambda: np.empty(0))  # Pa

    @property
    def f0(self) -> float:
        return float(1.0 / np.mean(self.period)) if self.period.size else float("nan")

    @property
    def closed_quotient(self) -> np.ndarray:
        """(n_cycles,) fraction of each cycle with a node in contact (contact_duration / period)."""
        return self.contact_duration / self.period

    @property
    def max_contact_pressure(self) -> np.ndarray:
        """Alias of ``max_contact_pressure_unconverged`` (time-step and mesh dependent)."""
        return self.max_contact_pressure_unconverged

    @property
    def mean_contact_pressure(self) -> np.ndarray:
        """Alias of ``mean_peak_contact_pressure_unconverged`` (time-step and mesh dependent)."""
        return self.mean_peak_contact_pressure_unconverged


@dataclass(frozen=True)
class SimResult:
    """One simulation, observed at the camera rate over the kept window.

    ``ok`` is False when the simulation failed (non-finite state, no oscillation is
    *not* a failure); then ``message`` says why and the arrays are empty.

    Shapes: n = frames at ``fps`` after discarding the transient; m = free-surface nodes.

    Attributes
    ----------
    t : (n,) s, from 0 at the start of the kept window.
    gaw : (n,) glottal area, mm^2.
    width : (n,) glottal width W, mm.
    flow : (n,) volume flow rate Q, m^3/s.
    contact_pressure : (n, m) Pa, per free-surface node (inferior to superior).
    contact_force : (n, m) N/m (force per unit fold length), per free-surface node.
    surface_z : (m,) mm, undeformed height of each free-surface node.
    cycles : per-cycle summaries.
    trajectories : (n, n_nodes, 2) mm nodal displacements, when requested.
    gaw_hr : (HR_OVERSAMPLE * (n - 1) + 1,) glottal area, mm^2, at ``HR_OVERSAMPLE * fps`` from the
        same start: the waveform between frames, for sub-frame phase alignment
        (:func:`vfcore.observe.align`).
    p_in : (n,) glottal inlet pressure, Pa, p_sub minus the subglottal resonator pressures, when
        ``SimConfig.subglottal_modes`` is set; empty otherwise (the inlet pressure is then p_sub).
    settled_at : s from the start, the time at which a settled response stopped the simulation
        (``SimConfig.early_stop``; every later step repeats the last state); 0 = it ran to the end.
    """

    ok: bool
    message: str
    params: Params
    config: SimConfig
    fps: float
    t: np.ndarray = field(default_factory=lambda: np.empty(0))
    gaw: np.ndarray = field(default_factory=lambda: np.empty(0))
    width: np.ndarray = field(default_factory=lambda: np.empty(0))
    flow: np.ndarray = field(default_factory=lambda: np.empty(0))
    contact_pressure: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))
    contact_force: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))
    surface_z: np.ndarray = field(default_factory=lambda: np.empty(0))
    cycles: CycleSummary | None = None
    trajectories: np.ndarray | None = None
    wall_time: float = 0.0
    gaw_hr: np.ndarray = field(default_factory=lambda: np.empty(0))
    p_in: np.ndarray = field(default_factory=lambda: np.empty(0))
    settled_at: float = 0.0

    @property
    def f0(self) -> float:
        return self.cycles.f0 if (self.ok and self.cycles is not None) else float("nan")
