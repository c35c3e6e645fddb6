"""Evidence that separates the causes, independent of the held-out fits.

- `scaling_with_drift`: ``ln |X_n| = c + p ln |X_1| + s t`` over blocks: the amplitude exponent
  p with a linear time trend (a slowly drifting coefficient) separated from it;
- `quadrature_scaling`: the same for the part of ``R_n`` in quadrature with ``n phi``;
- `phase_lock`: mean and spread of ``arg R_n`` and its distance from 0 / pi;
- `dc_coupling`: slope of the block offset against ``Re R_2`` (detector map +1, a
  gap-modulated force on resonance -3);
- `non_harmonic_peak`: the largest spectral line that is not a harmonic (higher mode);
- `quantisation_step`: the ADC step from the distinct values of the record;
- `gap_force_requirement`: the force gradient (and hence frequency drift) a gap-modulated
  power-law force would need to make the fitted 2nd harmonic (calibration-free).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from afmlearn.freeosc.track import HarmonicTrack

__all__ = ["dc_coupling", "gap_force_requirement", "non_harmonic_peak", "phase_lock",
           "quadrature_scaling", "quantisation_step", "scaling_with_drift"]


def _ols(design: NDArray[np.float64], target: NDArray[np.float64]
         ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Least squares with residual-scaled standard errors: (coef, stderr)."""
    coef, *_ = np.linalg.lstsq(design, target, rcond=None)
    resid = target - design @ coef
    dof = max(target.size - design.shape[1], 1)
    cov = float(resid @ resid) / dof * np.linalg.pinv(design.T @ design)
    return coef, np.sqrt(np.diag(cov))


def scaling_with_drift(track: HarmonicTrack, harmonic: int) -> dict[str, float]:
    """Amplitude exponent of harmonic n, ``|R_n|``, with a linear time trend.

    Returns
    -------
    dict
        ``exponent``, ``exponent_stderr`` (dimensionless), ``drift_per_s``,
        ``drift_stderr`` (relative change of ``|X_n|`` per second at fixed amplitude),
        ``log_amplitude_range``; NaN when fewer than 4 blocks.
    """
    return _scaling(track, harmonic, np.abs(_harmonic(track, harmonic)))


def quadrature_scaling(track: HarmonicTrack, harmonic: int) -> dict[str, float]:
    """`scaling_with_drift` of the quadrature part ``|Im R_n|`` alone: the part an
    instantaneous map cannot make. A fixed-amplitude drive gives exponent 0 for it too."""
    return _scaling(track, harmonic, np.abs(_harmonic(track, harmonic).imag))


def _harmonic(track: HarmonicTrack, harmonic: int) -> NDArray[np.complex128]:
    if not 2 <= harmonic <= track.harmonics.shape[1]:
        raise ValueError(f"harmonic must be in [2, {track.harmonics.shape[1]}], got {harmonic}")
    return track.harmonics[:, harmonic - 1]


def _scaling(track: HarmonicTrack, harmonic: int, values: NDArray[np.float64]
             ) -> dict[str, float]:
    la = np.log(track.amplitude)
    out = {"exponent": math.nan, "exponent_stderr": math.nan, "drift_per_s": math.nan,
           "drift_stderr": math.nan, "log_amplitude_range": float(np.ptp(la)) if la.size else 0.0}
    if la.size < 4 or not np.all(values > 0):
        return out
    t = track.time_s - track.time_s.mean()
    design = np.column_stack([np.ones_like(la), la - la.mean(), t])
    coef, se = _ols(design, np.log(values))
    out.update(exponent=float(coef[1]), exponent_stderr=float(se[1]),
               drift_per_s=float(coef[2]), drift_stderr=float(se[2]))
    return out


def phase_lock(track: HarmonicTrack, harmonic: int) -> dict[str, float]:
    """Phase of ``R_n`` relative to ``n phi``: circular mean [rad], its spread across blocks
    [rad], and the distance of the mean from the nearest of 0 and pi [rad]."""
    z = track.harmonics[:, harmonic - 1]
    unit = z / np.abs(z)
    mean = complex(unit.mean())
    ang = math.atan2(mean.imag, mean.real)
    spread = math.sqrt(max(-2.0 * math.log(max(abs(mean), 1e-300)), 0.0))
    off = min(abs(ang), math.pi - abs(ang))
    return {"mean_rad": ang, "spread_rad": spread, "offset_from_real_rad": off}


def dc_coupling(track: HarmonicTrack) -> dict[str, float]:
    """Slope ``d offset / d Re(R_2)`` across blocks (with a linear time trend removed).

    A detector map ``b2 x^2`` moves the dc level and ``Re R_2`` together (+1); a force through
    the lever's transfer function moves the dc level by ``H(0)/H(2 Omega)`` (-3 on
    resonance). Returns ``slope``, ``stderr``; NaN when fewer than 4 blocks.
    """
    r2 = track.harmonics[:, 1].real
    if r2.size < 4:
        return {"slope": math.nan, "stderr": math.nan}
    t = track.time_s - track.time_s.mean()
    design = np.column_stack([np.ones_like(r2), r2 - r2.mean(), t])
    coef, se = _ols(design, track.offset)
    return {"slope": float(coef[1]), "stderr": float(se[1])}


def non_harmonic_peak(y: ArrayLike, *, sample_rate_hz: float, carrier_hz: float,
                      exclude_hz: float) -> dict[str, float]:
    """Largest spectral line above ``1.5 f_c`` farther than ``exclude_hz`` from any harmonic.

    Returns ``frequency_hz`` and ``relative`` (its amplitude / the fundamental's, Hann
    window): a higher mode shows as a line well above the noise floor.
    """
    y = np.asarray(y, dtype=float)
    spec = np.abs(np.fft.rfft((y - y.mean()) * np.hanning(y.size)))
    f = np.fft.rfftfreq(y.size, 1.0 / sample_rate_hz)
    k = np.round(f / carrier_hz)
    mask = (f > 1.5 * carrier_hz) & (np.abs(f - k * carrier_hz) > exclude_hz)
    fund = spec[np.abs(f - carrier_hz) < exclude_hz].max()
    if not mask.any():
        return {"frequency_hz": math.nan, "relative": 0.0}
    i = int(np.flatnonzero(mask)[np.argmax(spec[mask])])
    return {"frequency_hz": float(f[i]), "relative": float(spec[i] / fund)}


def quantisation_step(y: ArrayLike) -> float:
    """The ADC step of a quantised record (median spacing of its distinct values), record
    units; NaN when the record has more distinct values than a tenth of its samples."""
    y = np.asarray(y, dtype=float)
    values = np.unique(y)
    if values.size < 2 or values.size > y.size / 10:
        return math.nan
    return float(np.median(np.diff(values)))


def gap_force_requirement(f2: float, amplitude: float, *, harmonic_drift: float,
                          exponents: tuple[int, ...] = (1, 2, 3)) -> dict[str, Any]:
    """What a gap-modulated power-law force needs to make the fitted 2nd harmonic.

    A force ``F ~ z^-m`` at rest gap ``z`` expanded in the motion has
    ``F''/F' = (m + 1)/z``; the fitted ``f2 = F''/(2k)`` at amplitude ``A`` without contact
    (``z >= A``) therefore needs a gradient ``F'/k >= 2 f2 A / (m + 1)`` (``f2 A`` is
    dimensionless: no calibration enters). If the harmonics drift by a fraction ``eps`` at a
    fixed amplitude, such a force (``F'' ~ z^-(m+2)``) changed by ``eps``, its gradient by
    ``(m + 1)/(m + 2) eps``, and the oscillation frequency
    (``f ~ sqrt(1 - F'/k)``) by ``|df/f| >= (1/2) (m + 1)/(m + 2) eps g / (1 - g)``,
    ``g = F'/k``.

    Parameters
    ----------
    f2 : float
        Fitted ``F''/(2k)`` [1/record unit] (`GapModulatedForce` coefficient 0).
    amplitude : float
        Mean oscillation amplitude, record units.
    harmonic_drift : float
        Relative change of the 2nd harmonic at fixed amplitude over the record.
    exponents : tuple of int
        Power laws m to evaluate (1: sphere close to a plane, 2: plane-plane ...).

    Returns
    -------
    dict
        ``f2_times_amplitude`` and per m ``gradient_min`` (F'/k, >= 1: the lever would snap
        in) and ``frequency_change_min`` (fraction).
    """
    out: dict[str, Any] = {"f2_times_amplitude": float(abs(f2) * amplitude)}
    eps = abs(harmonic_drift)
    for m in exponents:
        g = 2.0 * abs(f2) * amplitude / (m + 1)
        df = math.inf if g >= 1 else 0.5 * (m + 1) / (m + 2) * eps * g / (1 - g)
        out[f"m{m}"] = {"gradient_min": g, "frequency_change_min": df}
    return out
