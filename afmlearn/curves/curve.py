"""One lock-in curve in the analysis' dimensionless units (lengths / free amplitude)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import final

import numpy as np
from numpy.typing import NDArray

__all__ = ["Curve"]

#: fraction of the approach (furthest from the sample) taken as the free reference
FAR_FRACTION = 0.15


@final
@dataclass(frozen=True)
class Curve:
    """Amplitude and phase versus piezo position, dimensionless.

    Attributes
    ----------
    tau : ndarray, shape (m,)
        Sample times ``omega0 t`` from the first sample.
    amplitude : ndarray, shape (m,)
        First-harmonic amplitude / ``length_m``.
    phase : ndarray, shape (m,)
        Lag of the deflection behind the drive [rad] (``pi/2`` on free resonance).
    z_piezo : ndarray, shape (m,)
        Piezo position / ``length_m`` (larger = further from the sample), arbitrary origin.
    segment : ndarray of int8, shape (m,)
        0 approach, 1 retraction.
    quality_factor : float
        Q of the free fundamental.
    spring_constant_n_per_m, resonance_frequency_hz, length_m : float
        SI scales: force unit ``k length_m``, time unit ``1 / (2 pi f0)``; ``length_m`` is the
        free amplitude measured on the far part of the approach.
    drive_frequency_hz : float
        Drive frequency.
    """

    tau: NDArray[np.float64]
    amplitude: NDArray[np.float64]
    phase: NDArray[np.float64]
    z_piezo: NDArray[np.float64]
    segment: NDArray[np.int8]
    quality_factor: float
    spring_constant_n_per_m: float
    resonance_frequency_hz: float
    length_m: float
    drive_frequency_hz: float

    @classmethod
    def from_si(cls, *, amplitude_m, phase_rad, z_piezo_m, segment, sample_rate_hz: float,
                quality_factor: float, spring_constant_n_per_m: float,
                resonance_frequency_hz: float, drive_frequency_hz: float | None = None
                ) -> Curve:
        """From SI arrays (shape (m,) each) and the calibration; checks the input.

        Raises
        ------
        ValueError
            Naming the argument, for wrong shapes, non-finite values, a curve without an
            approach segment or fewer than 20 points.
        """
        a = np.asarray(amplitude_m, dtype=float)
        ph = np.asarray(phase_rad, dtype=float)
        z = np.asarray(z_piezo_m, dtype=float)
        seg = np.asarray(segment).astype(np.int8)
        for name, arr in (("phase_rad", ph), ("z_piezo_m", z), ("segment", seg)):
            if arr.shape != a.shape:
                raise ValueError(f"{name} must have the shape of amplitude_m {a.shape}, got "
                                 f"{arr.shape}")
        if a.ndim != 1 or a.size < 20:
            raise ValueError(f"amplitude_m must be 1-D with >= 20 points, got shape {a.shape}")
        for name, arr in (("amplitude_m", a), ("phase_rad", ph), ("z_piezo_m", z)):
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{name} contains NaN or inf")
        if not np.any(seg == 0):
            raise ValueError("segment: the curve has no approach points (segment == 0)")
        for name, v in (("sample_rate_hz", sample_rate_hz), ("quality_factor", quality_factor),
                        ("spring_constant_n_per_m", spring_constant_n_per_m),
                        ("resonance_frequency_hz", resonance_frequency_hz)):
            if not (math.isfinite(float(v)) and float(v) > 0.0):
                raise ValueError(f"{name} must be a finite number > 0, got {v!r}")
        f0 = float(resonance_frequency_hz)
        fd = f0 if drive_frequency_hz is None else float(drive_frequency_hz)
        app = np.flatnonzero(seg == 0)
        far = app[: max(int(FAR_FRACTION * app.size), 5)]
        length = float(np.median(a[far]))
        if not length > 0.0:
            raise ValueError("amplitude_m: the free amplitude (far part of the approach) "
                             "must be > 0")
        tau = 2.0 * math.pi * f0 * np.arange(a.size) / float(sample_rate_hz)
        return cls(tau=tau, amplitude=a / length, phase=ph, z_piezo=z / length, segment=seg,
                   quality_factor=float(quality_factor),
                   spring_constant_n_per_m=float(spring_constant_n_per_m),
                   resonance_frequency_hz=f0, length_m=length, drive_frequency_hz=fd)

    @classmethod
    def from_trace(cls, trace) -> Curve:
        """From an :class:`afmlearn.io.Trace` with lock-in fields (``amplitude_m``,
        ``phase_rad``, ``z_piezo_m`` or ``gap_m``, optional ``segment``)."""
        amp = getattr(trace, "amplitude_m", None)
        phase = getattr(trace, "phase_rad", None)
        if amp is None or phase is None:
            raise ValueError("trace: not a lock-in curve (amplitude_m and phase_rad needed)")
        z = getattr(trace, "z_piezo_m", None)
        if z is None:
            z = trace.gap_m
        if np.ndim(z) != 1:
            raise ValueError("trace: a lock-in curve needs z_piezo_m or gap_m of shape (n,)")
        seg = getattr(trace, "segment", None)
        if seg is None:
            turn = int(np.argmin(z))
            seg = (np.arange(np.size(z)) > turn).astype(np.int8)
        fd = trace.drive_frequency_hz
        return cls.from_si(amplitude_m=amp, phase_rad=phase, z_piezo_m=z, segment=seg,
                           sample_rate_hz=trace.sample_rate_hz,
                           quality_factor=trace.quality_factor,
                           spring_constant_n_per_m=trace.spring_constant_n_per_m,
                           resonance_frequency_hz=trace.resonance_frequency_hz,
                           drive_frequency_hz=float(np.mean(fd)) if fd is not None else None)

    # ------------------------------------------------------------------ derived
    @property
    def n(self) -> int:
        return int(self.tau.size)

    @property
    def force_unit_n(self) -> float:
        return self.spring_constant_n_per_m * self.length_m

    @property
    def energy_unit_j(self) -> float:
        return self.spring_constant_n_per_m * self.length_m**2

    @property
    def omega(self) -> float:
        """Drive frequency / f0."""
        return self.drive_frequency_hz / self.resonance_frequency_hz

    def far(self) -> NDArray[np.int64]:
        """Indices of the free reference part (start of the approach)."""
        app = np.flatnonzero(self.segment == 0)
        return app[: max(int(FAR_FRACTION * app.size), 5)]

    @property
    def free_phase(self) -> float:
        """Median lag on the free reference part [rad]."""
        return float(np.median(self.phase[self.far()]))

    def noise(self) -> tuple[float, float]:
        """(amplitude, phase [rad]) noise std from second differences of the far part (MAD).

        Second differences remove slow trends; for white noise their variance is 6 sigma**2.
        """
        idx = self.far()
        out = []
        for arr in (self.amplitude, self.phase):
            d = np.diff(arr[idx], 2)
            s = 1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(6.0)
            out.append(max(float(s), 1e-6))
        return out[0], out[1]

    def subset(self, mask: NDArray[np.bool_]) -> Curve:
        """The points where ``mask`` is true (same scales)."""
        return Curve(tau=self.tau[mask], amplitude=self.amplitude[mask],
                     phase=self.phase[mask], z_piezo=self.z_piezo[mask],
                     segment=self.segment[mask], quality_factor=self.quality_factor,
                     spring_constant_n_per_m=self.spring_constant_n_per_m,
                     resonance_frequency_hz=self.resonance_frequency_hz,
                     length_m=self.length_m, drive_frequency_hz=self.drive_frequency_hz)
