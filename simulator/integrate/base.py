"""Integrators: strategies (objects) that advance a batch of systems over one segment."""

from __future__ import annotations

import abc
import math
from collections.abc import Sequence

import numpy as np

from ..forces.law import pack_laws
from ..system import System
from .state import Segment, State

__all__ = ["AbstractIntegrator", "pack"]


def pack(systems: Sequence[System], omega: np.ndarray) -> dict[str, np.ndarray]:
    """Per-trajectory arrays for the compiled kernels (see ``_kernel.integrate_segment``)."""
    b = len(systems)
    m = systems[0].n_modes
    out = {
        "dc": np.zeros((b, m)), "ds": np.zeros((b, m)), "ybase": np.zeros(b),
        "K": np.zeros((b, m)), "Dair": np.zeros((b, m)), "Dcon": np.zeros((b, m)),
        "S": np.zeros((b, m)),
    }
    cache: dict[int, object] = {}
    laws = []
    for i, s in enumerate(systems):
        cl = s.cantilever
        out["dc"][i], out["ds"][i] = s.excitation.modal_drive(cl, float(omega[i]))
        out["ybase"][i] = s.excitation.gap_modulation
        out["K"][i], out["Dair"][i] = cl.stiffness, cl.damping
        out["Dcon"][i], out["S"][i] = cl.contact_damping, cl.force_gain
        key = id(s.force)
        if key not in cache:
            cache[key] = s.force.law()
        laws.append(cache[key])
    out["kinds"], out["p1"], out["p2"], out["coefs"], out["header"] = pack_laws(laws)
    return out


class AbstractIntegrator(abc.ABC):
    """Advance ``B`` trajectories by ``n_samples`` output samples of spacing ``dt``.

    Subclasses implement the single hook :meth:`_advance`, which integrates in place.
    """

    @abc.abstractmethod
    def _advance(self, state: State, arrays: dict[str, np.ndarray], omega: np.ndarray,
                 gap_rate: np.ndarray, dt: float, n_samples: int, substeps: int,
                 out: dict[str, np.ndarray], record_velocity: bool) -> None:
        """Integrate in place: update ``state`` and fill ``out`` (q, v, force, contact)."""

    def steps_per_sample(self, systems: Sequence[System], omega: np.ndarray, dt: float) -> int:
        """Internal steps per output sample (1 unless the strategy refines)."""
        return 1

    def run(
        self,
        systems: System | Sequence[System],
        state: State,
        *,
        omega: float | Sequence[float] | np.ndarray,
        n_samples: int,
        dt: float,
        gap_rate: float | Sequence[float] | np.ndarray = 0.0,
        record_velocity: bool = False,
    ) -> Segment:
        """Integrate one segment, starting from ``state`` (left unchanged).

        Parameters
        ----------
        systems : System or sequence of System, length B
            One system for all trajectories, or one per trajectory.
        state : State
            Start state, batch size B.
        omega : float or array, shape (B,)
            Drive frequency ``Omega`` of each trajectory (> 0).
        n_samples : int
            Number of output samples (>= 1).
        dt : float
            Output sample interval (dimensionless, > 0).
        gap_rate : float or array, shape (B,)
            ``d g / d tau`` of the rest gap (approach ramp); 0 for a fixed gap.
        record_velocity : bool
            Also record modal velocities.

        Returns
        -------
        Segment
        """
        b = state.batch
        systems = [systems] * b if isinstance(systems, System) else list(systems)
        if len(systems) != b:
            raise ValueError(f"systems: need 1 or {b} systems for a batch of {b}, got "
                             f"{len(systems)}")
        if any(s.n_modes != state.q.shape[1] for s in systems):
            raise ValueError("systems: n_modes must match the state's number of modes")
        om = np.array(np.broadcast_to(np.asarray(omega, dtype=float), (b,)))
        if not np.all(np.isfinite(om)) or np.any(om <= 0):
            raise ValueError(f"omega must be finite and > 0, got {om}")
        gr = np.array(np.broadcast_to(np.asarray(gap_rate, dtype=float), (b,)))
        if not np.all(np.isfinite(gr)):
            raise ValueError("gap_rate must be finite")
        n_samples = int(n_samples)
        if n_samples < 1:
            raise ValueError(f"n_samples must be >= 1, got {n_samples}")
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be finite and > 0, got {dt}")
        arrays = pack(systems, om)
        start = state.copy()
        end = state.copy()
        m = state.q.shape[1]
        out = {
            "q": np.empty((b, m, n_samples)),
            "v": np.empty((b, m, n_samples if record_velocity else 0)),
            "force": np.empty((b, n_samples)),
            "contact": np.empty((b, n_samples), dtype=np.int8),
        }
        substeps = self.steps_per_sample(systems, om, float(dt))
        self._advance(end, arrays, om, gr, float(dt), n_samples, substeps, out, record_velocity)
        if not (np.all(np.isfinite(end.q)) and np.all(np.isfinite(end.v))):
            raise FloatingPointError(
                "integration diverged (NaN/inf): the tip may have crossed z = 0 with a model "
                "that has no repulsion there, or the step is too large; refine the step")
        return Segment(
            q=out["q"], v=out["v"] if record_velocity else None, force=out["force"],
            contact=out["contact"], tau_start=start.tau.copy(), theta_start=start.theta.copy(),
            gap_start=start.gap.copy(), omega=om, gap_rate=gr, gap_modulation=arrays["ybase"],
            dt=float(dt), start=start, end=end)
