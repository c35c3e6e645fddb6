"""Measurement chain: what the detector and the digitiser do to the true deflection.

Stages are objects applied in order by :class:`SensorChain` (default order as in an
instrument: detector nonlinearity -> detector low-pass -> noise -> ADC quantisation). All
stages work on dimensionless deflection with a reference amplitude ``x_ref`` (the free
amplitude) that sets the scale of noise, nonlinearity and ADC range.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Sequence
from typing import Any, final

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from .forces.base import check_range

__all__ = [
    "AbstractSensorStage",
    "GaussianNoise",
    "LowPass",
    "Quantizer",
    "DetectorNonlinearity",
    "SensorChain",
]


class AbstractSensorStage(abc.ABC):
    """One stage of the measurement chain."""

    @abc.abstractmethod
    def apply(self, x: NDArray[np.float64], *, x_ref: float, dt: float,
              rng: np.random.Generator) -> NDArray[np.float64]:
        """Return the stage output for input ``x`` of shape (..., n) sampled every ``dt``.

        ``dt`` is dimensionless (``omega0 * sample interval``).
        """

    def to_dict(self) -> dict[str, Any]:
        return {"stage": type(self).__name__, **{k: v for k, v in vars(self).items()}}


@final
class GaussianNoise(AbstractSensorStage):
    """Additive white Gaussian noise with standard deviation ``level * x_ref``.

    Parameters
    ----------
    level : float
        Relative noise level in [0, 1] (default 0.01 = 1 % of the free amplitude).
    """

    def __init__(self, *, level: float = 0.01) -> None:
        self.level = check_range("level", level, low=0.0, high=1.0)

    def apply(self, x, *, x_ref, dt, rng):
        if self.level == 0.0:
            return x
        return x + rng.normal(0.0, self.level * x_ref, size=x.shape)


@final
class LowPass(AbstractSensorStage):
    """Causal Butterworth low-pass of the detector.

    Parameters
    ----------
    cutoff : float
        Cut-off frequency in units of ``f0``, > 0 (must lie below the Nyquist frequency).
    order : int
        Filter order in [1, 8].
    """

    def __init__(self, *, cutoff: float, order: int = 2) -> None:
        self.cutoff = check_range("cutoff", cutoff, low=0.0, low_open=True)
        self.order = int(check_range("order", order, low=1, high=8))

    def apply(self, x, *, x_ref, dt, rng):
        nyquist = math.pi / dt  # in units of omega0 -> f/f0 = nyquist_omega
        wn = self.cutoff / nyquist
        if not 0.0 < wn < 1.0:
            raise ValueError(f"cutoff must lie below the Nyquist frequency ({nyquist:g} f0), "
                             f"got {self.cutoff}")
        sos = signal.butter(self.order, wn, output="sos")
        return signal.sosfilt(sos, x, axis=-1)


@final
class Quantizer(AbstractSensorStage):
    """ADC: clip to ``+- full_scale * x_ref`` and round to ``bits`` bits.

    Parameters
    ----------
    bits : int
        Resolution in [2, 32].
    full_scale : float
        Half range in units of ``x_ref``, > 0 (default 2).
    """

    def __init__(self, *, bits: int = 16, full_scale: float = 2.0) -> None:
        self.bits = int(check_range("bits", bits, low=2, high=32))
        self.full_scale = check_range("full_scale", full_scale, low=0.0, low_open=True)

    def apply(self, x, *, x_ref, dt, rng):
        half = self.full_scale * x_ref
        lsb = 2.0 * half / (2**self.bits)
        return np.clip(np.round(x / lsb) * lsb, -half, half - lsb)


@final
class DetectorNonlinearity(AbstractSensorStage):
    """Instantaneous detector map ``y/x_ref = u + a2 u**2 + a3 u**3`` with ``u = x / x_ref``.

    Parameters
    ----------
    a2, a3 : float
        Quadratic and cubic coefficients, each in [-0.5, 0.5] (a monotone map on |u| <= 1).
    """

    def __init__(self, *, a2: float = 0.0, a3: float = 0.0) -> None:
        self.a2 = check_range("a2", a2, low=-0.5, high=0.5)
        self.a3 = check_range("a3", a3, low=-0.5, high=0.5)

    def apply(self, x, *, x_ref, dt, rng):
        u = x / x_ref
        return x_ref * (u + self.a2 * u**2 + self.a3 * u**3)


@final
class SensorChain:
    """Ordered measurement stages with their own seeded random generator.

    Parameters
    ----------
    stages : sequence of AbstractSensorStage
        Applied in order (empty: perfect sensor).
    seed : int or None
        Seed of the noise generator.
    """

    def __init__(self, stages: Sequence[AbstractSensorStage] = (), *, seed: int | None = 0) -> None:
        for s in stages:
            if not isinstance(s, AbstractSensorStage):
                raise ValueError(f"stages: expected sensor stages, got {type(s).__name__}")
        self.stages = tuple(stages)
        self.seed = seed
        self._rng = np.random.default_rng(seed)

    @classmethod
    def default(cls, *, noise_level: float = 0.01, seed: int | None = 0) -> SensorChain:
        """Gaussian noise only (1 % of the free amplitude by default)."""
        return cls([GaussianNoise(level=noise_level)], seed=seed)

    def __call__(self, x: NDArray[np.float64], *, x_ref: float, dt: float) -> NDArray[np.float64]:
        """Measured signal for true deflection ``x`` (shape (..., n), dimensionless)."""
        check_range("x_ref", x_ref, low=0.0, low_open=True)
        y = np.asarray(x, dtype=float)
        for s in self.stages:
            y = s.apply(y, x_ref=x_ref, dt=dt, rng=self._rng)
        return y

    def to_dict(self) -> dict[str, Any]:
        return {"seed": self.seed, "stages": [s.to_dict() for s in self.stages]}
