"""Library terms: one candidate function of the tip--sample force each.

A term is a function ``theta(z, z', x; a0)`` of the instantaneous gap ``z``, its rate ``z'``,
the deflection ``x`` and the contact onset ``a0`` (all dimensionless: lengths / ``L_ref``,
time ``tau = omega0 t``). The identified tip--sample force is ``F_ts = sum_j c_j theta_j`` with
``F_ts > 0`` repulsive (physics.md section 1); the deflection equation is

    x'' + D x' + K x = -F_ts + B cos(Omega tau - phi).

Every term has a plain NumPy implementation (:meth:`AbstractTerm.evaluate`) and a compact
numeric encoding (``kind``, ``params``) that the compiled simulation kernel evaluates; the two
are tested against each other. Terms of the form ``g(z) z'`` also provide a *potential*
``G`` with ``dG/dtau = g(z) z'``, so that the weak formulation never differentiates data.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import final

import numpy as np
from numpy.typing import NDArray

from simulator.forces.law import Kind  # the one table of family codes (shared kernel)

__all__ = ["AbstractTerm", "TermInput", "Kind"]

FloatArray = NDArray[np.float64]


@final
@dataclass(frozen=True)
class TermInput:
    """The state a library is evaluated on (dimensionless).

    Parameters
    ----------
    z : ndarray, shape (n,)
        Instantaneous tip--sample gap / ``L_ref``.
    zdot : ndarray, shape (n,)
        Gap rate ``dz/dtau``.
    x : ndarray, shape (n,)
        Deflection / ``L_ref`` (towards the sample positive).
    a0 : float
        Contact onset / ``L_ref``: contact while ``z <= a0``.
    """

    z: FloatArray
    zdot: FloatArray
    x: FloatArray
    a0: float

    @property
    def in_contact(self) -> NDArray[np.bool_]:
        """Contact mask ``z <= a0``, shape (n,)."""
        return self.z <= self.a0

    @property
    def indentation(self) -> FloatArray:
        """``delta = max(a0 - z, 0)``, shape (n,)."""
        return np.maximum(self.a0 - self.z, 0.0)


class AbstractTerm(abc.ABC):
    """One candidate force function. Subclasses are frozen dataclasses and final.

    The abstract hook is :meth:`evaluate`; :attr:`kind` and :attr:`params` encode the term for
    the compiled kernel, :meth:`potential` is optional.
    """

    #: kernel family code (a :class:`Kind` constant)
    kind: int = 0

    @property
    @abc.abstractmethod
    def name(self) -> str:
        """Readable name, e.g. ``"delta^1.5"`` or ``"z^-2 [z>a0]"``."""

    @property
    @abc.abstractmethod
    def params(self) -> tuple[float, float]:
        """Two numeric parameters of the kernel encoding (unused ones are 0)."""

    @abc.abstractmethod
    def evaluate(self, s: TermInput) -> FloatArray:
        """Term values, shape (n,), on the state ``s`` (plain NumPy reference)."""

    def potential(self, s: TermInput) -> FloatArray | None:
        """``G`` with ``dG/dtau = theta`` along any trajectory, shape (n,); None if none exists."""
        return None

    @property
    def uses_velocity(self) -> bool:
        """True when the term depends on ``z'`` (a dissipative candidate)."""
        return False

    @property
    def contact_only(self) -> bool:
        """True when the term vanishes out of contact (``z > a0``)."""
        return False

    @property
    def sign(self) -> int:
        """Physically allowed sign of the force coefficient: +1 (>= 0), -1 (<= 0), 0 (free).

        Passivity and positive elasticity: an elastic contact pushes the tip out (``delta^p``:
        +1), a damping term removes energy (``c g(z) z'`` with ``g >= 0`` does work
        ``c g z'^2`` on the tip, so ``c <= 0``; ``delta^p delta'``: +1), an electrostatic
        sphere--plane force attracts (-1), van der Waals powers ``z^-n``, ``n <= 6``, attract
        and Pauli walls, ``n >= 7``, repel. Terms that can act either way return 0.
        """
        return 0

    def latex(self) -> str:
        """Name in a form suited to figure labels (mathtext)."""
        return self.name

    def __str__(self) -> str:
        return self.name


def fmt(p: float) -> str:
    """Compact exponent/parameter formatting for term names (``1.5``, ``2``, ``0.05``)."""
    return f"{p:g}"
