"""Mode and detector factor of the thermal method: ``k = C k_B T / <x*^2>``.

``<x*^2>`` is the mean square of the first mode's peak in the spectrum, in the units the
instrument reports. ``C`` depends on what those units mean (Butt & Jaschke 1995,
Nanotechnology 6, 1; Hutter & Bechhoefer 1993 for ``C = 1``):

- `ThermalCorrection.optical_lever()` ``C = 0.817``: rectangular lever, first mode only,
  deflection from an optical lever whose sensitivity (InvOLS) was calibrated on a static,
  end-loaded bend. The lever measures the slope; a first-mode shape has a tip slope 1.09
  times that of the static bend of the same tip deflection, so ``C = 0.971 / 1.09^2``.
- `ThermalCorrection.displacement()` ``C = 0.971``: first mode only, true tip displacement
  (interferometer, or an optical lever calibrated dynamically); 0.971 = 12 / alpha_1^4 is the
  first mode's share of the thermal energy of a clamped-free beam.
- `ThermalCorrection.point_mass()` ``C = 1``: an ideal single-degree-of-freedom oscillator
  (used for synthetic checks).

No Sader (hydrodynamic) step is involved: the thermal method needs the spectrum in metres,
i.e. a calibrated detector sensitivity; errors in it enter k squared.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import final

__all__ = ["ThermalCorrection"]


@final
@dataclass(frozen=True)
class ThermalCorrection:
    """The factor ``C`` of ``k = C k_B T / <x*^2>`` and what it assumes.

    Parameters
    ----------
    factor : float
        ``C``, > 0.
    description : str
        What the factor assumes (written into calibration.json).
    """

    factor: float
    description: str

    def __post_init__(self) -> None:
        if not self.factor > 0:
            raise ValueError(f"factor must be > 0, got {self.factor!r}")

    @classmethod
    def optical_lever(cls) -> ThermalCorrection:
        """Butt & Jaschke 1995: first mode, optical lever with static InvOLS (0.817)."""
        return cls(0.817, "Butt & Jaschke 1995: rectangular lever, first mode, optical lever "
                          "deflection with a static (end-loaded) InvOLS, C = 0.971 / 1.09^2")

    @classmethod
    def displacement(cls) -> ThermalCorrection:
        """First mode, true tip displacement (0.971)."""
        return cls(0.971, "rectangular lever, first mode, true tip displacement, "
                          "C = 12 / alpha_1^4 = 0.971")

    @classmethod
    def point_mass(cls) -> ThermalCorrection:
        """An ideal one-degree-of-freedom oscillator (1)."""
        return cls(1.0, "ideal single-degree-of-freedom oscillator, C = 1")

    @classmethod
    def named(cls, name: str) -> ThermalCorrection:
        """One of ``"optical_lever"``, ``"displacement"``, ``"point_mass"``."""
        presets = {"optical_lever": cls.optical_lever, "displacement": cls.displacement,
                   "point_mass": cls.point_mass}
        if name not in presets:
            raise ValueError(f"correction must be one of {sorted(presets)}, got {name!r}")
        return presets[name]()
