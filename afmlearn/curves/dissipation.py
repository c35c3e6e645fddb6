"""Energy dissipated in the tip--sample junction per cycle, from amplitude and phase.

Cleveland, Anczykowski, Schmid, Elings, APL 72, 2613 (1998); Anczykowski, Gotsmann, Fuchs,
Cleveland, Elings, Appl. Surf. Sci. 140, 376 (1999): energy balance of the steady single-mode
lever, drive in = viscous loss of the lever + tip--sample loss. With the drive force fixed by
the free state (``B sin(phi_f) = A_f W / Q``) it reads, per drive cycle::

    E_ts = (pi k A W / Q) (A_f sin(phi) / sin(phi_f) - A)

which is their ``(pi k / Q)(A_f A sin(phi) - A**2 W)`` when driven at resonance
(``phi_f = pi/2``). Only valid where the amplitude is steady (slow ramps).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["dissipated_energy"]


def dissipated_energy(amplitude: ArrayLike, phase: ArrayLike, *, free_amplitude: float,
                      free_phase: float, quality_factor: float, omega: float = 1.0,
                      spring_constant: float = 1.0) -> NDArray[np.float64]:
    """Tip--sample energy loss per cycle.

    Parameters
    ----------
    amplitude : array-like, shape (m,)
        Amplitude (any length unit ``L``).
    phase : array-like, shape (m,)
        Lag of the deflection behind the drive [rad].
    free_amplitude : float
        Free amplitude at the same drive (units of ``amplitude``).
    free_phase : float
        Free lag [rad] (``pi/2`` at resonance).
    quality_factor : float
        Q of the free lever.
    omega : float
        Drive frequency / f0.
    spring_constant : float
        ``k`` [N/m] with amplitudes in metres gives joules; 1 gives units of ``k L**2``.

    Returns
    -------
    ndarray, shape (m,)
        Energy into the sample per drive cycle (> 0 dissipated).
    """
    a = np.asarray(amplitude, dtype=float)
    ph = np.asarray(phase, dtype=float)
    if not (quality_factor > 0 and free_amplitude > 0 and math.sin(free_phase) > 0):
        raise ValueError("quality_factor, free_amplitude must be > 0 and free_phase in (0, pi)")
    return (math.pi * spring_constant * a * omega / quality_factor
            * (free_amplitude * np.sin(ph) / math.sin(free_phase) - a))
