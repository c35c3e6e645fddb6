"""`Trace`: one cantilever recording (measured or simulated) in SI units."""

from __future__ import annotations

from dataclasses import KW_ONLY, dataclass, fields
from typing import Any, Literal, final

import numpy as np

from afmlearn.io._checks import (
    FloatArray,
    finite_array,
    finite_number,
    optional_positive,
    positive,
    text,
)
from afmlearn.io.labels import Labels

__all__ = ["Trace", "EXCITATIONS"]

Excitation = Literal["tip", "base"]
EXCITATIONS: tuple[str, ...] = ("tip", "base")


@final
@dataclass(frozen=True, eq=False)
class Trace:
    """One recording: a single trace or a frequency sweep, with its calibration.

    A measured and a simulated trace are the same object; simulated ones carry ``labels``.
    Arrays are stored as read-only float64 arrays; everything is validated on construction
    and bad values raise ``ValueError`` naming the field.

    Parameters
    ----------
    deflection_m : array-like, shape (n,) or (n_points, n)
        Tip deflection [m], towards the sample positive; 2-D for a sweep (one row per drive
        frequency).
    sample_rate_hz : float
        Sampling rate of every array [Hz], > 0.
    spring_constant_n_per_m : float
        Spring constant k from thermal calibration [N/m], > 0.
    quality_factor : float
        Q of the free fundamental [-], > 0.
    resonance_frequency_hz : float
        f0 of the free fundamental [Hz], > 0.
    drive_frequency_hz : float or array-like, shape (n_points,)
        Drive frequency [Hz], > 0; an array (one per row) exactly when the trace is a sweep.
    gap_m : float or array-like, shape (n,)
        Rest tip-sample gap with the cantilever undeflected [m]; an array when it varies in
        time (approach ramp). Finite.
    free_amplitude_m : float, optional
        Steady free amplitude at the drive frequency far from the sample [m], > 0.
    excitation : {"tip", "base"}, optional
        How the cantilever is driven; None means unknown (analyses assume "tip").
    dither_amplitude_m : float, optional
        Base (dither) motion amplitude [m], > 0, for ``excitation == "base"``.
    higher_mode_frequencies_hz : array-like, shape (n_higher,), optional
        Measured f2, f3, ... [Hz], > 0.
    tip_radius_m : float, optional
        Nominal tip radius [m], > 0.
    description : str, optional
        Free text.
    free_deflection_m : array-like, shape (m,), optional
        Deflection with the same drive far from the sample [m].
    labels : Labels, optional
        Ground truth of a simulated trace.
    """

    deflection_m: FloatArray
    _: KW_ONLY
    sample_rate_hz: float
    spring_constant_n_per_m: float
    quality_factor: float
    resonance_frequency_hz: float
    drive_frequency_hz: float | FloatArray
    gap_m: float | FloatArray
    free_amplitude_m: float | None = None
    excitation: Excitation | None = None
    dither_amplitude_m: float | None = None
    higher_mode_frequencies_hz: FloatArray | None = None
    tip_radius_m: float | None = None
    description: str | None = None
    free_deflection_m: FloatArray | None = None
    labels: Labels | None = None

    def __post_init__(self) -> None:
        deflection = finite_array("deflection_m", self.deflection_m, ndim=(1, 2))
        object.__setattr__(self, "deflection_m", deflection)
        checked = check_metadata(
            n_points=deflection.shape[0] if deflection.ndim == 2 else None,
            n_samples=deflection.shape[-1],
            **{name: getattr(self, name) for name in METADATA_FIELDS},
        )
        for name, value in checked.items():
            object.__setattr__(self, name, value)
        if self.labels is not None:
            if not isinstance(self.labels, Labels):
                raise ValueError(f"labels must be a Labels or None, got {self.labels!r}")
            self.labels.check_shape(deflection.shape)

    @property
    def is_sweep(self) -> bool:
        """True when ``deflection_m`` is 2-D (one row per drive frequency)."""
        return self.deflection_m.ndim == 2

    @property
    def n_samples(self) -> int:
        """Number of samples n per row."""
        return self.deflection_m.shape[-1]

    @property
    def n_points(self) -> int:
        """Number of rows (drive frequencies) of a sweep; 1 for a single trace."""
        return self.deflection_m.shape[0] if self.is_sweep else 1

    @property
    def dt_s(self) -> float:
        """Sampling interval [s]."""
        return 1.0 / self.sample_rate_hz

    @property
    def time_s(self) -> FloatArray:
        """Sample times [s], shape (n,), starting at 0."""
        return np.arange(self.n_samples) / self.sample_rate_hz

    def metadata(self) -> dict[str, Any]:
        """Everything but ``deflection_m`` and ``labels``, as keyword arguments of `Trace`."""
        return {name: getattr(self, name) for name in METADATA_FIELDS}


METADATA_FIELDS: tuple[str, ...] = tuple(
    f.name for f in fields(Trace) if f.name not in ("deflection_m", "labels")
)


def check_metadata(
    *,
    n_points: int | None,
    n_samples: int,
    sample_rate_hz: Any,
    spring_constant_n_per_m: Any,
    quality_factor: Any,
    resonance_frequency_hz: Any,
    drive_frequency_hz: Any,
    gap_m: Any,
    free_amplitude_m: Any = None,
    excitation: Any = None,
    dither_amplitude_m: Any = None,
    higher_mode_frequencies_hz: Any = None,
    tip_radius_m: Any = None,
    description: Any = None,
    free_deflection_m: Any = None,
) -> dict[str, Any]:
    """Validate the metadata of a trace with ``n_points`` rows (None: single) of ``n_samples``.

    Returns the normalised values keyed by field name; raises ``ValueError`` naming the field.
    """
    if n_points is None:
        if np.ndim(drive_frequency_hz) != 0:
            raise ValueError(
                "drive_frequency_hz must be a single number when deflection_m is 1-D, "
                f"got shape {np.shape(drive_frequency_hz)}"
            )
        drive = positive("drive_frequency_hz", drive_frequency_hz)
    else:
        if np.shape(drive_frequency_hz) != (n_points,):
            raise ValueError(
                "drive_frequency_hz must be an array of shape (n_points,) = "
                f"({n_points},) when deflection_m is 2-D (a sweep), "
                f"got shape {np.shape(drive_frequency_hz)}"
            )
        drive = finite_array("drive_frequency_hz", drive_frequency_hz, ndim=(1,), positive=True)
    if np.ndim(gap_m) == 0:
        gap = finite_number("gap_m", gap_m)
    elif np.shape(gap_m) != (n_samples,):
        raise ValueError(
            f"gap_m must be a number or an array of shape (n,) = ({n_samples},), "
            f"got shape {np.shape(gap_m)}"
        )
    else:
        gap = finite_array("gap_m", gap_m, ndim=(1,))
    if excitation is not None:
        excitation = text("excitation", excitation)
        if excitation not in EXCITATIONS:
            raise ValueError(f"excitation must be one of {EXCITATIONS} or None, got {excitation!r}")
    if higher_mode_frequencies_hz is not None:
        higher_mode_frequencies_hz = finite_array(
            "higher_mode_frequencies_hz",
            np.atleast_1d(higher_mode_frequencies_hz),
            ndim=(1,),
            positive=True,
        )
    return {
        "sample_rate_hz": positive("sample_rate_hz", sample_rate_hz),
        "spring_constant_n_per_m": positive("spring_constant_n_per_m", spring_constant_n_per_m),
        "quality_factor": positive("quality_factor", quality_factor),
        "resonance_frequency_hz": positive("resonance_frequency_hz", resonance_frequency_hz),
        "drive_frequency_hz": drive,
        "gap_m": gap,
        "free_amplitude_m": optional_positive("free_amplitude_m", free_amplitude_m),
        "excitation": excitation,
        "dither_amplitude_m": optional_positive("dither_amplitude_m", dither_amplitude_m),
        "higher_mode_frequencies_hz": higher_mode_frequencies_hz,
        "tip_radius_m": optional_positive("tip_radius_m", tip_radius_m),
        "description": None if description is None else text("description", description),
        "free_deflection_m": None
        if free_deflection_m is None
        else finite_array("free_deflection_m", free_deflection_m, ndim=(1,)),
    }
