"""Frequency sweep, forward and/or reverse, each point continuing from the previous state."""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any, final

import numpy as np
from numpy.typing import NDArray

from ..forces.base import check_range
from ..integrate.state import Segment, State
from ..labels import segment_labels
from ..system import System
from .base import AbstractScenario, settle
from .result import SimulationResult

__all__ = ["Sweep", "SweepPoint", "stack_labels"]

_DIRECTIONS = ("forward", "reverse", "both")


@final
@dataclass(frozen=True)
class SweepPoint:
    """One recorded point of one sweep direction.

    Attributes
    ----------
    row : int
        Row in the output (forward rows first, then reverse rows).
    direction : str
        ``forward`` or ``reverse``.
    omega : float
        Drive frequency of the point.
    segment : Segment
        The integrated segment (batch of all directions; use ``batch``).
    batch : int
        Index of this direction in the segment's batch.
    labels : dict
        Scalar labels of the point.
    """

    row: int
    direction: str
    omega: float
    segment: Segment
    batch: int
    labels: dict[str, Any]

    @property
    def q(self) -> NDArray[np.float64]:
        """Modal deflections, shape (M, n)."""
        return self.segment.q[self.batch]

    @property
    def force(self) -> NDArray[np.float64]:
        return self.segment.force[self.batch]

    @property
    def gap(self) -> NDArray[np.float64]:
        return self.segment.gap[self.batch]

    @property
    def contact(self) -> NDArray[np.int8]:
        return self.segment.contact[self.batch]

    @property
    def phase(self) -> NDArray[np.float64]:
        return self.segment.phase[self.batch]

    @property
    def rest_gap(self) -> NDArray[np.float64]:
        return self.segment.rest_gap[self.batch]


@final
class Sweep(AbstractScenario):
    """Stepped frequency sweep as an instrument runs it.

    The sampling rate is fixed in physical time: ``samples_per_period`` counts samples per
    period of the free resonance ``f0`` (``dt = 2 pi / samples_per_period``). Each point
    continues from the previous point's end state with a phase-continuous drive. With
    ``direction="both"`` the forward and reverse sweeps run as one batch (in parallel).

    Parameters
    ----------
    omega_start, omega_stop : float
        First and last drive frequency of the forward sweep (> 0, start < stop).
    n_points : int
        Points per direction (>= 2).
    samples_per_point : int
        Recorded samples per point (>= 1).
    settle_samples : int
        Samples integrated, not recorded, before each point (default 0: continuous).
    direction : {"forward", "reverse", "both"}
    gap : float
        Rest gap.
    settle_periods : float or None
        Settling at the first point (default ``2.5 Q_1`` periods).
    """

    name = "sweep"

    def __init__(self, *, omega_start: float = 0.99, omega_stop: float = 1.13,
                 n_points: int = 101, samples_per_point: int = 20_000, settle_samples: int = 0,
                 direction: str = "both", gap: float = 1.0,
                 **kwargs) -> None:
        kwargs.setdefault("samples_per_period", 1500.0)
        super().__init__(**kwargs)
        self.omega_start = check_range("omega_start", omega_start, low=0.0, low_open=True)
        self.omega_stop = check_range("omega_stop", omega_stop, low=self.omega_start,
                                      low_open=True)
        self.n_points = int(check_range("n_points", n_points, low=2))
        self.samples_per_point = int(check_range("samples_per_point", samples_per_point, low=1))
        self.settle_samples = int(check_range("settle_samples", settle_samples, low=0))
        if direction not in _DIRECTIONS:
            raise ValueError(f"direction must be one of {_DIRECTIONS}, got {direction!r}")
        self.direction = direction
        self.gap = check_range("gap", gap, low=0.0, low_open=True)

    @property
    def dt(self) -> float:
        return 2.0 * math.pi / self.samples_per_period

    @property
    def omegas(self) -> NDArray[np.float64]:
        """Forward frequencies, shape (n_points,)."""
        return np.linspace(self.omega_start, self.omega_stop, self.n_points)

    @property
    def directions(self) -> tuple[str, ...]:
        return ("forward", "reverse") if self.direction == "both" else (self.direction,)

    @property
    def n_rows(self) -> int:
        return self.n_points * len(self.directions)

    def row_omegas(self) -> NDArray[np.float64]:
        """Drive frequency of each output row, shape (n_rows,)."""
        w = self.omegas
        return np.concatenate([w if d == "forward" else w[::-1] for d in self.directions])

    def total_samples(self, system: System) -> int:
        sp = self.settle_periods_for(system)
        settle_n = sp * self.samples_per_period / self.omega_start
        return int(math.ceil(settle_n + self.n_points * (self.samples_per_point
                                                         + self.settle_samples)))

    def iter_points(self, system: System, *, progress=None) -> Iterator[SweepPoint]:
        """Yield the points as they are computed (both directions advance together)."""
        w = self.omegas
        dirs = self.directions
        schedule = np.stack([w if d == "forward" else w[::-1] for d in dirs])  # (B, P)
        state = State.free_orbit(system, omega=schedule[:, 0], gap=self.gap)
        sp = self.settle_periods_for(system)
        # settle each direction at its first frequency (batch members may differ)
        state = settle(system, state, integrator=self.integrator, omega=schedule[:, 0],
                       dt=self.dt, periods=sp, progress=progress)
        for k in range(self.n_points):
            om = schedule[:, k]
            if self.settle_samples:
                state = self.integrator.run(system, state, omega=om,
                                            n_samples=self.settle_samples, dt=self.dt).end
            seg = self.integrator.run(system, state, omega=om, n_samples=self.samples_per_point,
                                      dt=self.dt, record_velocity=self.record_velocity)
            state = seg.end
            if progress is not None:
                progress(self.samples_per_point + self.settle_samples)
            for b, d in enumerate(dirs):
                row = k + b * self.n_points
                yield SweepPoint(row=row, direction=d, omega=float(om[b]), segment=seg, batch=b,
                                 labels=segment_labels(seg, b))

    def run(self, system: System, *, progress=None) -> SimulationResult:
        """Run the whole sweep into memory (rows: forward points, then reverse points)."""
        rows = self.n_rows
        m, n = system.n_modes, self.samples_per_point
        q = np.empty((rows, m, n))
        vel = np.empty((rows, m, n)) if self.record_velocity else None
        force = np.empty((rows, n))
        gap = np.empty((rows, n))
        rest = np.empty((rows, n))
        contact = np.empty((rows, n), dtype=np.int8)
        phase = np.empty((rows, n))
        labels: list[dict[str, Any]] = [{}] * rows
        for p in self.iter_points(system, progress=progress):
            q[p.row] = p.q
            if vel is not None:
                vel[p.row] = p.segment.v[p.batch]
            force[p.row], gap[p.row], rest[p.row] = p.force, p.gap, p.rest_gap
            contact[p.row], phase[p.row] = p.contact, p.phase
            labels[p.row] = p.labels
        meta = self.to_dict()
        meta["direction_of_row"] = [d for d in self.directions for _ in range(self.n_points)]
        return SimulationResult(
            system=system, scenario=self.name, dt=self.dt, omega=self.row_omegas(), q=q,
            force=force, gap=gap, rest_gap=rest, contact=contact, phase=phase,
            labels=stack_labels(labels), meta=meta, velocity=vel)


def stack_labels(labels: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Per-row label dicts -> dict of arrays (strings become lists)."""
    out: dict[str, Any] = {}
    for key in labels[0]:
        vals = [lab[key] for lab in labels]
        out[key] = vals if isinstance(vals[0], str) else np.asarray(vals, dtype=float)
    return out
