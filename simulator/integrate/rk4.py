"""Fixed-step classical RK4 with located contact events (compiled, batched over threads)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import final

import numpy as np

from ..forces.law import ForceLaw, Kind
from ..system import System
from ._kernel import integrate_segment
from .base import AbstractIntegrator
from .state import State

__all__ = ["RK4"]


@final
class RK4(AbstractIntegrator):
    """Classical 4th-order Runge--Kutta, fixed step, events located inside the step.

    Parameters
    ----------
    substeps : int or None
        Steps per output sample. ``None`` (default) picks the smallest number that gives at
        least ``steps_per_period`` steps per period of the fastest motion (highest mode, drive,
        or the stiffened contact oscillation).
    steps_per_period : int
        Resolution target of the automatic choice (default 120, error ~1e-8 per period).
    """

    def __init__(self, *, substeps: int | None = None, steps_per_period: int = 120) -> None:
        if substeps is not None and (int(substeps) != substeps or substeps < 1):
            raise ValueError(f"substeps must be a positive integer or None, got {substeps!r}")
        if steps_per_period < 8:
            raise ValueError(f"steps_per_period must be >= 8, got {steps_per_period!r}")
        self.substeps = None if substeps is None else int(substeps)
        self.steps_per_period = int(steps_per_period)

    def steps_per_sample(self, systems: Sequence[System], omega: np.ndarray, dt: float) -> int:
        if self.substeps is not None:
            return self.substeps
        w = float(np.max(omega))
        for s in systems:
            k_last = float(s.cantilever.stiffness[-1])
            w = max(w, math.sqrt(k_last), _contact_frequency(s.force.law(), k_last))
        return max(1, math.ceil(self.steps_per_period * dt * w / (2.0 * math.pi)))

    def _advance(self, state: State, arrays, omega, gap_rate, dt, n_samples, substeps, out,
                 record_velocity) -> None:
        integrate_segment(
            state.q, state.v, state.contact, state.tau, state.theta, omega, arrays["dc"],
            arrays["ds"], arrays["ybase"], state.gap, gap_rate, arrays["K"], arrays["Dair"],
            arrays["Dcon"], arrays["S"], arrays["kinds"], arrays["p1"], arrays["p2"],
            arrays["coefs"], arrays["header"], state.work, dt, n_samples, substeps,
            out["q"], out["v"], out["force"], out["contact"], record_velocity)

    def __repr__(self) -> str:
        return f"RK4(substeps={self.substeps!r}, steps_per_period={self.steps_per_period})"


def _contact_frequency(law: ForceLaw, k_last: float) -> float:
    """Angular frequency of the stiffened oscillation in contact (0 without a wall)."""
    w = 0.0
    if law.has_contact:
        for t in law.terms:
            if t.kind == Kind.INDENTATION:
                # contact stiffness at an indentation of 10 % of the gap
                kc = t.coef * t.p1 * 0.1 ** (t.p1 - 1.0)
                w = max(w, math.sqrt(k_last + kc))
            elif t.kind == Kind.JKR_CUBE:
                w = max(w, math.sqrt(1.0 + t.coef * t.p1**1.5))
    rep = law.coefficient(Kind.INVERSE_POWER, 8.0)
    if rep > 0.0:
        # wall stiffness 6 c_a / z*^3 where repulsion balances attraction, x4 for taps that
        # push further into the wall
        ca = max(-law.coefficient(Kind.INVERSE_POWER, 2.0), 1e-3)
        zs = (rep / ca) ** (1.0 / 6.0)
        w = max(w, math.sqrt(1.0 + 24.0 * ca / zs**3))
    return w
