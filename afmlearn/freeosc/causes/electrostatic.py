"""Electrostatic forces of a Kelvin-probe bias on a freely oscillating lever.

``F = -(1/2) C'(z) (V_dc - V_cpd + V_ac cos(omega_e t))^2``. Two ways for it to make
harmonics, each its own cause object:

- `AcBiasDrive`: an ac bias at the oscillation frequency drives the lever at ``2 omega``
  with a force ``~ V_ac^2`` **independent of the oscillation amplitude**; the lever answers
  through ``H(2 Omega)``: a harmonic of fixed complex amplitude relative to ``2 phi`` (the bias
  follows the oscillation in a self-oscillating KPFM loop).
- `GapModulatedForce`: the gap ``z + x`` modulates a static electrostatic force,
  ``F(z + x) = F + F' x + F'' x^2/2 + F''' x^3/6``: force harmonics scale as ``A^n`` like a
  detector map, but the lever filters them, ``x_n = H(n Omega) F_n / k``, and the dc term
  through ``H(0) = 1``: the dc level moves with ``A^2`` by ``H(0)/H(2 Omega) = 1 - 4 Omega^2``
  (-3 on resonance) times the 2nd harmonic's coefficient, where a detector map gives +1. The
  phase of ``H(n Omega)`` departs from pi by ``n / ((n^2 - 1) Q)``.

``H(n Omega) = 1 / (1 - n^2 Omega^2 + i n Omega / Q)``, ``Omega`` = oscillation / resonance
frequency (1 for a self-oscillating lever).
"""

from __future__ import annotations

import math
from typing import final

import numpy as np

from afmlearn.freeosc.causes.base import AbstractCause, FloatArray
from afmlearn.freeosc.demodulate import Demodulation

__all__ = ["AcBiasDrive", "GapModulatedForce", "transfer"]


def transfer(n: int, *, omega: float = 1.0, quality_factor: float = math.inf) -> complex:
    """The lever's response ``H(n Omega)`` to a force ``k e^{i n Omega tau}`` (dimensionless)."""
    damping = 0.0 if math.isinf(quality_factor) else n * omega / quality_factor
    return 1.0 / complex(1.0 - (n * omega) ** 2, damping)


@final
class AcBiasDrive(AbstractCause):
    """Columns ``cos 2phi, sin 2phi``: a 2nd harmonic of fixed amplitude and phase
    (``coef_`` record units)."""

    name = "electrostatic"
    equation = "y = c + A cos(phi) + Re(C2 e^{2 i phi})  [ac bias: force ~ V_ac^2 at 2 omega]"

    def _columns(self, demod: Demodulation) -> FloatArray:
        p = demod.phase
        return np.column_stack([np.cos(2 * p), np.sin(2 * p)])


@final
class GapModulatedForce(AbstractCause):
    """Columns ``A^2/2 (H(0) + Re(H(2) e^{2 i phi}))`` and ``A^3/4 Re(H(3) e^{3 i phi})``;
    ``coef_ = [F''/(2k), F'''/(6k)]`` in 1/record unit and 1/record unit^2.

    Parameters
    ----------
    omega : float, default 1
        Oscillation / resonance frequency, > 0 (1: self-oscillation at resonance).
    quality_factor : float, default inf
        Q > 0 of the lever (inf: the high-Q limit, a real transfer function).
    """

    name = "electrostatic"
    equation = ("y = c + A cos(phi) + H * (f2 x^2 + f3 x^3)  [gap-modulated force, "
                "filtered by H(n Omega)]")

    def __init__(self, *, omega: float = 1.0, quality_factor: float = math.inf) -> None:
        if not (math.isfinite(omega) and omega > 0):
            raise ValueError(f"omega must be > 0, got {omega!r}")
        if not quality_factor > 0:
            raise ValueError(f"quality_factor must be > 0, got {quality_factor!r}")
        self.omega = omega
        self.quality_factor = quality_factor

    def _columns(self, demod: Demodulation) -> FloatArray:
        a, p = demod.amplitude, demod.phase
        h0 = transfer(0, omega=self.omega, quality_factor=self.quality_factor)
        h2 = transfer(2, omega=self.omega, quality_factor=self.quality_factor)
        h3 = transfer(3, omega=self.omega, quality_factor=self.quality_factor)
        g2 = a**2 / 2 * (h0.real + (h2 * np.exp(2j * p)).real)
        g3 = a**3 / 4 * (h3 * np.exp(3j * p)).real
        return np.column_stack([g2, g3])
