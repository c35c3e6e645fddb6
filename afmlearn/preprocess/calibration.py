"""Calibration: the dimensionless view of one trace row (``physics.md`` section 1).

``calibrate(trace)`` turns SI samples into ``tau = omega0 t``, ``x = deflection / L_ref`` with
``L_ref`` = the mean rest gap, and estimates the dimensionless drive-force amplitude ``F_c``
(``B`` in ``x'' + x'/Q + x = -F_ts + B cos(Omega tau)``) from the free (no-interaction) data.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, final

import numpy as np
from numpy.typing import NDArray

from afmlearn.io import Trace
from afmlearn.preprocess.harmonics import fit_harmonics
from simulator import Scales

__all__ = ["Calibrated", "DriveSource", "calibrate", "free_drive_amplitude"]

FloatArray = NDArray[np.float64]
DriveSource = Literal["free_deflection", "free_amplitude", "none"]

#: a free trace is used for F_c only when it spans at least this many drive periods
MIN_FREE_PERIODS = 2.0
#: relative frequency mismatch above which the free trace is taken to run at another frequency
_FREQ_TOL = 1e-3


@final
@dataclass(frozen=True, eq=False)
class Calibrated:
    """Dimensionless view of one trace row (``physics.md`` section 1 conventions).

    Attributes
    ----------
    tau : ndarray, shape (n,)
        Dimensionless time ``omega0 t`` from the first sample (``omega0 = 2 pi f0``).
    x : ndarray, shape (n,)
        Deflection / ``L_ref``, towards the sample positive.
    gap : float or ndarray, shape (n,)
        Rest gap / ``L_ref`` (1.0 for a constant gap, since ``L_ref`` = mean rest gap).
    omega : float
        Drive frequency ``Omega = f_drive / f0``.
    quality_factor : float
        Q of the free fundamental.
    drive_amplitude : float or None
        ``F_c``: amplitude of the fundamental-frequency modal forcing, units of ``k L_ref``
        (``B`` of ``B cos(Omega tau)`` for tip excitation, ``B_1 Omega^2 y`` for base
        excitation); None when the trace has no free data.
    drive_source : {"free_deflection", "free_amplitude", "none"}
        Where ``drive_amplitude`` comes from.
    excitation : {"tip", "base"}
        Drive kind; "tip" when the file does not say (then ``excitation_assumed`` is True).
    excitation_assumed : bool
        True when ``excitation`` was not in the file.
    dither : float or None
        Base (dither) amplitude / ``L_ref``.
    scales : simulator.Scales
        ``k``, ``f0``, ``L_ref``: force unit ``k L_ref`` [N], time unit ``1/omega0`` [s].
    samples_per_period : float
        ``sample_rate / f_drive``.
    higher_mode_ratios : ndarray, shape (n_higher,), or None
        ``f_i / f0`` of measured higher modes.
    tip_radius : float or None
        Tip radius / ``L_ref``.
    row : int or None
        Row of a sweep (None for a single trace).
    """

    tau: FloatArray
    x: FloatArray
    gap: float | FloatArray
    omega: float
    quality_factor: float
    drive_amplitude: float | None
    drive_source: DriveSource
    excitation: Literal["tip", "base"]
    excitation_assumed: bool
    dither: float | None
    scales: Scales
    samples_per_period: float
    higher_mode_ratios: FloatArray | None
    tip_radius: float | None
    row: int | None

    @property
    def n_samples(self) -> int:
        """Number of samples n."""
        return self.x.size

    @property
    def dt(self) -> float:
        """Dimensionless sample interval ``omega0 / sample_rate``."""
        return 2.0 * math.pi / (self.omega * self.samples_per_period)

    @property
    def damping(self) -> float:
        """``D = 1 / Q``."""
        return 1.0 / self.quality_factor

    @property
    def n_periods(self) -> float:
        """Number of drive periods covered by the samples."""
        return self.n_samples / self.samples_per_period

    @property
    def force_unit_n(self) -> float:
        """Force unit ``k L_ref`` [N]: multiply a dimensionless force by this."""
        return self.scales.force


def calibrate(trace: Trace, *, row: int | None = None) -> Calibrated:
    """Dimensionless view of ``trace`` (row ``row`` of a sweep).

    Parameters
    ----------
    trace : afmlearn.io.Trace
        A validated trace (``read_trace`` / ``Trace``); its labels are never used.
    row : int, optional
        Row of a sweep, required for (and only for) sweeps.

    Returns
    -------
    Calibrated

    Notes
    -----
    ``L_ref`` is the mean rest gap ``mean(gap_m)`` (the gap itself when constant); it must be
    > 0. ``F_c`` (``drive_amplitude``) is taken, in order of preference, from

    1. ``free_deflection_m`` (when it spans >= 2 drive periods): a harmonic fit
       (`fit_harmonics`) of the free trace gives its fundamental ``X_1`` and, by projecting
       ``x'' + x'/Q + x = B_c cos + B_s sin`` on the fundamental with the fit's analytic
       derivatives, ``F_c = |X_1| |1 - Omega^2 + i Omega / Q|``. Its phase is not transferable
       (the free trace is recorded at another time), only its amplitude. If the free trace
       runs at a frequency other than the row's (sweeps: the free trace is recorded at one
       reference frequency), that frequency is measured from the free trace itself and ``F_c``
       is carried over as a frequency-independent force for tip excitation and scaled by
       ``(Omega / Omega_free)^2`` for base excitation (inertial forcing ``B_1 Omega^2 y``).
    2. ``free_amplitude_m``, assumed measured at the row's drive frequency:
       ``F_c = A_free / L_ref * |1 - Omega^2 + i Omega / Q|``.
    3. Otherwise None (``drive_source = "none"``).

    For base excitation ``F_c`` is the amplitude of the fundamental-frequency modal forcing
    ``B_1 Omega^2 y`` (same meaning as for tip excitation); it multiplies ``sin(Omega tau)``
    in the simulator's phase convention, which does not matter for an amplitude.

    Raises
    ------
    ValueError
        For a non-positive mean rest gap, or a ``row`` that does not fit the trace.
    """
    if not isinstance(trace, Trace):
        raise ValueError(f"trace must be an afmlearn.io.Trace, got {type(trace).__name__}")
    if trace.has_rows:
        if row is None or isinstance(row, bool) or not isinstance(row, int | np.integer) \
                or not 0 <= row < trace.n_points:
            raise ValueError(f"row must be an integer in [0, {trace.n_points}) for a sweep or "
                             f"a set-point series, got {row!r}")
        row = int(row)
        trace = trace.row(row)
        deflection = trace.deflection_m
        f_drive = float(trace.drive_frequency_hz)
    else:
        if row not in (None, 0):
            raise ValueError(f"row must be None (or 0) for a single trace, got {row!r}")
        row = None
        deflection = trace.deflection_m
        f_drive = float(trace.drive_frequency_hz)
    gap_m = trace.gap_m
    ell = float(np.mean(gap_m))
    if not ell > 0:
        raise ValueError(f"gap_m must have a mean > 0 (it sets L_ref), got {ell!r}")
    f0 = trace.resonance_frequency_hz
    scales = Scales(spring_constant=trace.spring_constant_n_per_m, resonance_frequency=f0,
                    length=ell)
    omega = f_drive / f0
    q = trace.quality_factor
    fs = trace.sample_rate_hz
    tau = _readonly(2.0 * math.pi * f0 / fs * np.arange(deflection.size))
    x = _readonly(np.asarray(deflection, dtype=float) / ell)
    gap: float | FloatArray = 1.0 if np.ndim(gap_m) == 0 else _readonly(np.asarray(gap_m) / ell)
    excitation = trace.excitation or "tip"

    drive, source = None, "none"
    free = trace.free_deflection_m
    if free is not None and free.size / (fs / f_drive) >= MIN_FREE_PERIODS:
        drive = free_drive_amplitude(free / ell, dt=2.0 * math.pi * f0 / fs, omega=omega,
                                     quality_factor=q, excitation=excitation)
        source = "free_deflection"
    elif trace.free_amplitude_m is not None:
        drive = trace.free_amplitude_m / ell * abs(1.0 - omega**2 + 1j * omega / q)
        source = "free_amplitude"
    higher = trace.higher_mode_frequencies_hz
    return Calibrated(
        tau=tau, x=x, gap=gap, omega=omega, quality_factor=q, drive_amplitude=drive,
        drive_source=source, excitation=excitation,
        excitation_assumed=trace.excitation is None,
        dither=None if trace.dither_amplitude_m is None else trace.dither_amplitude_m / ell,
        scales=scales, samples_per_period=fs / f_drive,
        higher_mode_ratios=None if higher is None else _readonly(np.asarray(higher) / f0),
        tip_radius=None if trace.tip_radius_m is None else trace.tip_radius_m / ell,
        row=row)


def free_drive_amplitude(x_free: FloatArray, *, dt: float, omega: float, quality_factor: float,
                         excitation: str = "tip") -> float:
    """Drive-force amplitude ``F_c`` at ``omega`` from a free (no-interaction) trace.

    Parameters
    ----------
    x_free : ndarray, shape (m,)
        Free deflection / ``L_ref``.
    dt : float
        Dimensionless sample interval ``omega0 / sample_rate``.
    omega : float
        Drive frequency at which ``F_c`` is wanted (``f_drive / f0``).
    quality_factor : float
        Q of the fundamental.
    excitation : {"tip", "base"}
        How ``F_c`` carries over when the free trace runs at another frequency (see
        `calibrate`).

    Returns
    -------
    float
        ``F_c`` in units of ``k L_ref``.
    """
    tau = dt * np.arange(x_free.size)
    omega_free = omega
    fit = fit_harmonics(tau, x_free, omega_free, n_harmonics=1)
    explained = 1.0 - fit.residual_rms**2 / max(float(np.var(x_free)), 1e-300)
    if explained < 0.9:  # not at this frequency: measure the free trace's own frequency
        omega_free = _dominant_frequency(tau, x_free, guess=omega)
        if abs(omega_free / omega - 1.0) < _FREQ_TOL:
            omega_free = omega
        fit = fit_harmonics(tau, x_free, omega_free, n_harmonics=1)
    x1 = abs(fit.complex_amplitudes[1])
    # projection of x'' + x'/Q + x on the fundamental, with the fit's analytic derivatives
    force = x1 * abs(1.0 - omega_free**2 + 1j * omega_free / quality_factor)
    if excitation == "base":
        force *= (omega / omega_free) ** 2
    return float(force)


def _dominant_frequency(tau: FloatArray, x: FloatArray, *, guess: float) -> float:
    """Angular frequency (units of omega0) of the strongest spectral line of ``x``.

    FFT peak with 8x zero padding, refined by a golden-section search within one padded bin
    for the frequency whose least-squares sinusoid (constant + cos + sin) leaves the smallest
    residual (unlike the lock-in power, unbiased by the negative-frequency image).
    """
    n = x.size
    dt = float(tau[1] - tau[0])
    y = x - x.mean()
    pad = 8 * n
    spec = np.abs(np.fft.rfft(y, pad))
    spec[0] = 0.0
    k = int(np.argmax(spec))
    w = 2 * np.pi * np.fft.rfftfreq(pad, dt)
    lo, hi = w[max(k - 1, 0)], w[min(k + 1, w.size - 1)]

    def power(v: float) -> float:
        return fit_harmonics(tau, x, v, n_harmonics=1).residual_rms

    g = (math.sqrt(5) - 1) / 2
    a, b = lo, hi
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = power(c), power(d)
    for _ in range(40):
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = power(c)
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = power(d)
    return float(0.5 * (a + b)) if w.size > 1 else guess


def _readonly(a: np.ndarray) -> FloatArray:
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a
