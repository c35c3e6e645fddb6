"""How the drive phase of each observation enters the joint fit: strategies.

Each observation starts at its own drive phase. When the instrument recorded it
(``Trace.drive_phase_rad``), :class:`RecordedPhase` rotates that observation's drive to it and
keeps the quadrature ``B sin(delta phi)`` under a Gaussian prior of the stated width (the
phase is USED, with its uncertainty, not refitted freely). Observations without a recorded
phase, and every observation under :class:`FittedPhase`, start with a free drive (two
unconstrained columns); :func:`afmlearn.identify.joint.estimate_phases` then picks their phase
(the free fit's or the conservative root of the fundamental's balance) and boxes the drive.
"""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass
from typing import final

import numpy as np

from .problem import JointProblem

__all__ = ["AbstractDrivePhase", "FittedPhase", "RecordedPhase"]


class AbstractDrivePhase(abc.ABC):
    """Initial drive columns of every observation (one hook)."""

    @abc.abstractmethod
    def initial(self, problem: JointProblem) -> JointProblem:
        """``problem`` with known phases rotated in (NaN rotation: fitted later)."""


@final
@dataclass(frozen=True)
class RecordedPhase(AbstractDrivePhase):
    """Use ``drive_phase_rad`` where the file has it, with a prior of ``width_rad``.

    Parameters
    ----------
    width_rad : float
        Standard deviation [rad] of the recorded phase (> 0; default 0.01 rad).
    """

    width_rad: float = 0.01

    def __post_init__(self) -> None:
        if not (isinstance(self.width_rad, int | float) and math.isfinite(self.width_rad)
                and self.width_rad > 0):
            raise ValueError(f"width_rad must be a finite number > 0, got {self.width_rad!r}")

    def initial(self, problem: JointProblem) -> JointProblem:
        rec = [o.recorded_phase for o in problem.observations]
        rot = np.array([math.nan if r is None else r for r in rec], float)
        widths = np.where(np.isfinite(rot), self.width_rad, np.inf)
        return problem.with_drive(rot, widths)


@final
@dataclass(frozen=True)
class FittedPhase(AbstractDrivePhase):
    """Ignore any recorded phase: every observation's phase is estimated from the data."""

    def initial(self, problem: JointProblem) -> JointProblem:
        n = problem.n_obs
        return problem.with_drive(np.full(n, np.nan), np.full(n, np.inf))
