"""Integrator state and the record of one integrated segment."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import final

import numpy as np
from numpy.typing import NDArray

from ..system import System
from ._kernel import N_WORK

__all__ = ["State", "Segment"]


@final
@dataclass
class State:
    """Dynamic state of ``B`` trajectories (dimensionless).

    Attributes
    ----------
    q, v : ndarray, shape (B, n_modes)
        Modal deflections (towards the sample) and velocities ``dq/dtau``.
    contact : ndarray of int8, shape (B,)
        Contact regime (history state; 1 in contact, 0 free; see ``_kernel``).
    tau : ndarray, shape (B,)
        Time.
    theta : ndarray, shape (B,)
        Drive phase at ``tau`` (continuous across frequency changes, as an instrument's DDS).
    gap : ndarray, shape (B,)
        Rest gap ``g`` at ``tau`` (the undeflected tip--sample distance).
    work : ndarray, shape (B, 5)
        Work integrals since the start: drive input, cantilever damping, work on the
        tip--sample force, energy into the sample, time in contact.
    """

    q: NDArray[np.float64]
    v: NDArray[np.float64]
    contact: NDArray[np.int8]
    tau: NDArray[np.float64]
    theta: NDArray[np.float64]
    gap: NDArray[np.float64]
    work: NDArray[np.float64] = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        self.q = np.array(self.q, dtype=np.float64, ndmin=2)
        self.v = np.array(self.v, dtype=np.float64, ndmin=2)
        b = self.q.shape[0]
        if self.v.shape != self.q.shape:
            raise ValueError(f"v must have the shape of q {self.q.shape}, got {self.v.shape}")
        self.contact = np.array(np.broadcast_to(self.contact, (b,)), dtype=np.int8)
        self.tau = np.array(np.broadcast_to(self.tau, (b,)), dtype=np.float64)
        self.theta = np.array(np.broadcast_to(self.theta, (b,)), dtype=np.float64)
        self.gap = np.array(np.broadcast_to(self.gap, (b,)), dtype=np.float64)
        self.work = (np.zeros((b, N_WORK)) if self.work is None
                     else np.array(self.work, dtype=np.float64).reshape(b, N_WORK))
        for name in ("q", "v", "tau", "theta", "gap", "work"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise ValueError(f"state.{name} contains NaN or inf")

    @property
    def batch(self) -> int:
        return self.q.shape[0]

    def copy(self) -> State:
        return State(self.q.copy(), self.v.copy(), self.contact.copy(), self.tau.copy(),
                     self.theta.copy(), self.gap.copy(), self.work.copy())

    @classmethod
    def free_orbit(
        cls,
        systems: System | Sequence[System],
        *,
        omega: float | Sequence[float],
        gap: float | Sequence[float] = 1.0,
        theta: float | Sequence[float] = 0.0,
        tau: float = 0.0,
    ) -> State:
        """Start on the linear free orbit at drive phase ``theta`` (an approach from far away).

        The contact regime is the approach branch at the initial gap.
        """
        systems = [systems] if isinstance(systems, System) else list(systems)
        b = max(len(systems), np.size(omega), np.size(gap), np.size(theta))
        if len(systems) == 1:
            systems = systems * b
        om = np.broadcast_to(np.asarray(omega, dtype=float), (b,))
        th = np.broadcast_to(np.asarray(theta, dtype=float), (b,))
        g = np.broadcast_to(np.asarray(gap, dtype=float), (b,))
        m = systems[0].n_modes
        q = np.zeros((b, m))
        v = np.zeros((b, m))
        contact = np.zeros(b, dtype=np.int8)
        for i, sysm in enumerate(systems):
            if sysm.n_modes != m:
                raise ValueError("systems: every trajectory of a batch needs the same n_modes")
            amp = sysm.excitation.free_response(sysm.cantilever, float(om[i]))
            ph = np.exp(1j * th[i])
            q[i] = (amp * ph).real
            v[i] = (1j * om[i] * amp * ph).real
            z = g[i] - q[i].sum() - sysm.excitation.gap_modulation * np.sin(th[i])
            contact[i] = int(bool(sysm.force.contact_state(z)))
        return cls(q, v, contact, np.full(b, tau), th.copy(), g.copy())


@final
@dataclass(frozen=True)
class Segment:
    """Samples of ``B`` trajectories over one integrated segment (dimensionless).

    Attributes
    ----------
    q : ndarray, shape (B, n_modes, n)
        Modal deflections at ``tau_start + k dt``.
    v : ndarray, shape (B, n_modes, n) or None
        Modal velocities (when recorded).
    force : ndarray, shape (B, n)
        Tip--sample force (positive = repulsive).
    contact : ndarray of int8, shape (B, n)
        Contact regime.
    tau_start, theta_start, gap_start, omega, gap_rate, gap_modulation : ndarray, shape (B,)
        Segment start time, drive phase and rest gap, drive frequency, gap ramp rate, base
        amplitude in the gap.
    dt : float
        Sample interval.
    start, end : State
        States at the start and end of the segment.

    Derived arrays (``tau``, ``deflection``, ``phase``, ``drive_cos``, ``drive_sin``,
    ``rest_gap``, ``gap``) are computed
    once, on first access, for the whole batch.
    """

    q: NDArray[np.float64]
    v: NDArray[np.float64] | None
    force: NDArray[np.float64]
    contact: NDArray[np.int8]
    tau_start: NDArray[np.float64]
    theta_start: NDArray[np.float64]
    gap_start: NDArray[np.float64]
    omega: NDArray[np.float64]
    gap_rate: NDArray[np.float64]
    gap_modulation: NDArray[np.float64]
    dt: float
    start: State
    end: State

    @property
    def n_samples(self) -> int:
        return self.q.shape[-1]

    @cached_property
    def tau(self) -> NDArray[np.float64]:
        """Sample times, shape (B, n)."""
        return self.tau_start[:, None] + self.dt * np.arange(self.n_samples)[None, :]

    @cached_property
    def deflection(self) -> NDArray[np.float64]:
        """Tip deflection ``x = sum_i q_i``, shape (B, n)."""
        return self.q.sum(axis=1)

    @cached_property
    def phase(self) -> NDArray[np.float64]:
        """Drive phase at each sample, shape (B, n)."""
        elapsed = self.tau - self.tau_start[:, None]
        return self.theta_start[:, None] + self.omega[:, None] * elapsed

    @cached_property
    def drive_cos(self) -> NDArray[np.float64]:
        """``cos(theta)`` at each sample, shape (B, n)."""
        return np.cos(self.phase)

    @cached_property
    def drive_sin(self) -> NDArray[np.float64]:
        """``sin(theta)`` at each sample, shape (B, n)."""
        return np.sin(self.phase)

    @cached_property
    def rest_gap(self) -> NDArray[np.float64]:
        """Rest gap ``g(tau)``, shape (B, n)."""
        elapsed = self.tau - self.tau_start[:, None]
        return self.gap_start[:, None] + self.gap_rate[:, None] * elapsed

    @cached_property
    def gap(self) -> NDArray[np.float64]:
        """Instantaneous tip--sample gap ``z``, shape (B, n)."""
        return self.rest_gap - self.deflection - self.gap_modulation[:, None] * self.drive_sin

    @property
    def work(self) -> NDArray[np.float64]:
        """Work integrals accumulated over the segment, shape (B, 5)."""
        return self.end.work - self.start.work
