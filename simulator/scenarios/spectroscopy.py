"""Dynamic spectroscopy: steady records at several rest gaps (a set-point series)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import final

import numpy as np
from numpy.typing import NDArray

from ..forces.base import check_range
from ..integrate.state import State
from ..labels import segment_labels
from ..system import System
from .base import AbstractScenario, settle
from .result import SimulationResult
from .sweep import stack_labels

__all__ = ["Spectroscopy", "DEFAULT_GAP_RATIOS"]

#: Default rest gaps as a fraction of the free amplitude: 8 set-points from 0.95 to 0.4.
DEFAULT_GAP_RATIOS: tuple[float, ...] = tuple(
    float(r) for r in np.round(np.linspace(0.95, 0.4, 8), 4)
)


def _positive_values(name: str, values: Sequence[float]) -> NDArray[np.float64]:
    arr = np.atleast_1d(np.asarray(values, dtype=float))
    if arr.ndim != 1 or arr.size == 0:
        raise ValueError(f"{name} must be a non-empty list of numbers, got {values!r}")
    for v in arr:
        check_range(name, float(v), low=0.0, low_open=True)
    return arr


@final
class Spectroscopy(AbstractScenario):
    """Steady records at N rest gaps, each settled from the free orbit (one row per gap).

    Each row is what an approach that stops at that gap records: the tip starts on the steady
    free orbit (far from the sample) and the rest gap steps to the row's gap, then the motion
    settles for ``settle_periods`` drive periods and ``n_periods`` periods are recorded. The
    rows are independent trajectories integrated as one batch, so row ``i`` equals a
    :class:`SteadyState` run at gap ``g_i`` with the same settings (up to the drive phase).

    Parameters
    ----------
    omega : float
        Drive frequency ``Omega = f / f0`` (> 0), the same for every row.
    gaps : sequence of float, optional
        Rest gaps in units of ``L_ref`` (> 0), one per row; when given it wins over
        ``gap_ratios``.
    gap_ratios : sequence of float
        Rest gaps as a fraction of the steady free amplitude at ``omega`` (> 0), used when
        ``gaps`` is None. Default: 8 values from 0.95 to 0.4.
    n_periods : float
        Recorded drive periods per row (> 0).
    drive_phases : sequence of float, optional
        Drive phase ``theta`` [rad] at each row's first recorded sample (one per row); None:
        every row starts its free orbit at ``theta = 0`` (as :class:`SteadyState`).
    settle_periods : float or None
        Periods integrated before recording; ``None``: ``2.5 Q_1``.
    samples_per_period, integrator, record_velocity :
        See :class:`AbstractScenario`.
    """

    name = "spectroscopy"

    def __init__(self, *, omega: float = 1.0, gaps: Sequence[float] | None = None,
                 gap_ratios: Sequence[float] = DEFAULT_GAP_RATIOS, n_periods: float = 50.0,
                 drive_phases: Sequence[float] | None = None, **kwargs) -> None:
        super().__init__(**kwargs)
        self.omega = check_range("omega", omega, low=0.0, low_open=True)
        self.gaps = None if gaps is None else _positive_values("gaps", gaps)
        self.gap_ratios = _positive_values("gap_ratios", gap_ratios)
        self.n_periods = check_range("n_periods", n_periods, low=0.0, low_open=True)
        n_rows = self.gap_ratios.size if self.gaps is None else self.gaps.size
        if drive_phases is None:
            self.drive_phases = None
        else:
            phases = np.atleast_1d(np.asarray(drive_phases, dtype=float))
            if phases.shape != (n_rows,) or not np.all(np.isfinite(phases)):
                raise ValueError(f"drive_phases must hold {n_rows} finite numbers (one per "
                                 f"gap), got {drive_phases!r}")
            self.drive_phases = phases

    @property
    def n_rows(self) -> int:
        """Number of rest gaps (rows)."""
        return self.gap_ratios.size if self.gaps is None else self.gaps.size

    def rest_gaps(self, free_amplitude: float) -> NDArray[np.float64]:
        """Rest gap of each row [L_ref], shape (n_rows,).

        Parameters
        ----------
        free_amplitude : float
            Steady free tip amplitude at ``omega`` [L_ref] (scales ``gap_ratios``).
        """
        if self.gaps is not None:
            return self.gaps.copy()
        check_range("free_amplitude", free_amplitude, low=0.0, low_open=True)
        return self.gap_ratios * free_amplitude

    def _settle_samples(self, system: System) -> int:
        """Samples `settle` integrates (the same expression, so the phases line up)."""
        periods = self.settle_periods_for(system)
        return int(math.ceil(periods * 2.0 * math.pi / (self.omega * self.dt)))

    def total_samples(self, system: System) -> int:
        n = int(round(self.n_periods * self.samples_per_period))
        return self.n_rows * (self._settle_samples(system) + n)

    def run(self, system: System, *, progress=None) -> SimulationResult:
        gaps = self.rest_gaps(system.excitation.free_amplitude(system.cantilever, self.omega))
        b = gaps.size
        theta0 = np.zeros(b)
        if self.drive_phases is not None:
            # the phase advances by omega * dt per sample: start the settling so that the
            # recording begins at the requested phase
            theta0 = self.drive_phases - self.omega * self.dt * self._settle_samples(system)
        state = State.free_orbit(system, omega=self.omega, gap=gaps, theta=theta0)
        state = settle(system, state, integrator=self.integrator, omega=np.full(b, self.omega),
                       dt=self.dt, periods=self.settle_periods_for(system),
                       progress=None if progress is None else (lambda m: progress(m * b)))
        n = int(round(self.n_periods * self.samples_per_period))
        seg = self.integrator.run(system, state, omega=np.full(b, self.omega), n_samples=n,
                                  dt=self.dt, record_velocity=self.record_velocity)
        if progress is not None:
            progress(n * b)
        meta = self.to_dict()
        meta["rest_gaps"] = gaps.tolist()
        return SimulationResult(
            system=system, scenario=self.name, dt=self.dt, omega=self.omega, q=seg.q,
            force=seg.force, gap=seg.gap, rest_gap=seg.rest_gap, contact=seg.contact,
            phase=seg.phase, labels=stack_labels([segment_labels(seg, i) for i in range(b)]),
            meta=meta, velocity=seg.v if self.record_velocity else None)
