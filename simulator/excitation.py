"""How the cantilever is driven: a force on the tip, or a dither motion of the base.

Strategies are objects (``TipExcitation``, ``BaseExcitation``); each turns a drive frequency
into modal drive coefficients and a gap modulation (``physics.md`` §2).
"""

from __future__ import annotations

import abc
from typing import final

import numpy as np
from numpy.typing import NDArray

from .cantilever import Cantilever
from .forces.base import check_range

__all__ = ["AbstractExcitation", "TipExcitation", "BaseExcitation"]


class AbstractExcitation(abc.ABC):
    """Drive of the cantilever at dimensionless angular frequency ``Omega``.

    The modal drive is ``cos_coef_i cos(theta) + sin_coef_i sin(theta)`` with the drive phase
    ``theta = Omega tau + theta0``; the gap is ``z = g - sum q_i - gap_modulation sin(theta)``.
    """

    #: value of the trace-format attribute ``excitation``
    kind: str = "abstract"

    def __init__(self, *, amplitude: float) -> None:
        self.amplitude = check_range("amplitude", amplitude, low=0.0)

    @abc.abstractmethod
    def modal_drive(
        self, cantilever: Cantilever, omega: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(cos_coef, sin_coef)``, each shape (n_modes,)."""

    @property
    def gap_modulation(self) -> float:
        """Amplitude of the base motion entering the gap (0 for tip excitation)."""
        return 0.0

    def free_response(self, cantilever: Cantilever, omega: float) -> NDArray[np.complex128]:
        """Complex modal amplitudes ``Q_i`` of the linear free orbit ``q_i = Re(Q_i e^{i theta})``.

        Returns
        -------
        ndarray, shape (n_modes,), complex
        """
        c, s = self.modal_drive(cantilever, omega)
        return (c - 1j * s) * cantilever.receptance(omega)

    def free_amplitude(self, cantilever: Cantilever, omega: float) -> float:
        """Steady free amplitude of the tip deflection ``|sum_i Q_i|`` (dimensionless)."""
        return float(abs(self.free_response(cantilever, omega).sum()))

    @classmethod
    def for_free_amplitude(
        cls, cantilever: Cantilever, omega: float, free_amplitude: float
    ) -> AbstractExcitation:
        """The excitation of this kind whose free tip amplitude at ``omega`` is given."""
        check_range("free_amplitude", free_amplitude, low=0.0, low_open=True)
        unit = cls(amplitude=1.0).free_amplitude(cantilever, omega)
        return cls(amplitude=free_amplitude / unit)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(amplitude={self.amplitude!r})"


@final
class TipExcitation(AbstractExcitation):
    """A harmonic force ``amplitude * cos(theta)`` on the tip (photothermal, magnetic, lumped).

    ``amplitude`` is the dimensionless force ``F_drive / (k L_ref)`` (``B`` in eq. 5.4).
    """

    kind = "tip"

    def modal_drive(self, cantilever: Cantilever, omega: float):
        return self.amplitude * np.asarray(cantilever.force_gain), np.zeros(cantilever.n_modes)


@final
class BaseExcitation(AbstractExcitation):
    """Dither piezo moving the base by ``amplitude * sin(theta)`` towards the sample.

    ``amplitude`` is the dither amplitude ``y`` in units of ``L_ref``. Each mode feels the
    inertial force ``B_i Omega**2 y sin(theta)``; the gap includes the base motion (eq. 3.2).
    """

    kind = "base"

    def modal_drive(self, cantilever: Cantilever, omega: float):
        b = np.asarray(cantilever.base_participation)
        return np.zeros(cantilever.n_modes), b * omega**2 * self.amplitude

    @property
    def gap_modulation(self) -> float:
        return self.amplitude
