"""`Trace`: one cantilever recording (measured or simulated) in SI units."""

from __future__ import annotations

from dataclasses import KW_ONLY, dataclass, fields
from typing import Any, Literal, final

import numpy as np
from numpy.typing import NDArray

from afmlearn.io._checks import (
    FloatArray,
    finite_array,
    finite_number,
    optional_positive,
    positive,
    segment_array,
    text,
)
from afmlearn.io.labels import Labels

__all__ = ["Trace", "EXCITATIONS", "SEGMENT_APPROACH", "SEGMENT_RETRACT"]

Excitation = Literal["tip", "base"]
EXCITATIONS: tuple[str, ...] = ("tip", "base")
#: Values of ``segment``: the approach and the retraction part of a ramp or curve.
SEGMENT_APPROACH = 0
SEGMENT_RETRACT = 1

#: Fields that hold one value per row of a 2-D trace (sliced by `Trace.row`).
_PER_ROW = ("drive_frequency_hz", "gap_m", "drive_phase_rad")


@final
@dataclass(frozen=True, eq=False)
class Trace:
    """One recording: a single trace, a frequency sweep, a set-point series, a ramp or curves.

    A measured and a simulated trace are the same object; simulated ones carry ``labels``.
    Arrays are stored as read-only arrays; everything is validated on construction and bad
    values raise ``ValueError`` naming the field. The kinds (design.md section 2):

    - single steady record: 1-D ``deflection_m``, scalar ``gap_m`` and ``drive_frequency_hz``;
    - approach/retract ramp: 1-D ``deflection_m`` with ``gap_m`` of shape (n,) (and ``segment``);
    - frequency sweep: 2-D ``deflection_m`` with ``drive_frequency_hz`` of shape (n_points,);
    - set-point series: 2-D ``deflection_m`` with ``gap_m`` of shape (n_points,) (row ``i`` is a
      steady record at rest gap ``gap_m[i]``, same drive);
    - lock-in curves: ``amplitude_m`` / ``phase_rad`` of shape (n,) versus ``z_piezo_m`` or
      ``gap_m``; ``deflection_m`` may then be None.

    Parameters
    ----------
    deflection_m : array-like, shape (n,) or (n_points, n), or None
        Tip deflection [m], towards the sample positive; 2-D for a sweep or a series (one row
        per drive frequency / rest gap). None only for lock-in curves (``amplitude_m`` given).
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
    gap_m : float or array-like, shape (n,) or (n_points,)
        Rest tip-sample gap with the cantilever undeflected [m]; shape (n,) when it varies in
        time (approach ramp), shape (n_points,) for a set-point series (2-D deflection). Finite.
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
    drive_phase_rad : float or array-like, shape (n_points,), optional
        Phase of the drive at each row's first sample [rad]: the drive is proportional to
        ``cos(2 pi f_d t + drive_phase_rad)`` with ``t = 0`` at that sample, positive towards
        the sample. An array only for a 2-D deflection. None: not recorded.
    segment : array-like of int, shape (n,), optional
        For ramps and curves: ``0`` approach, ``1`` retraction (stored as int8).
    amplitude_m : array-like, shape (n,), optional
        Lock-in first-harmonic amplitude of the deflection [m], >= 0.
    phase_rad : array-like, shape (n,), optional
        Lock-in phase [rad]: lag of the deflection behind the drive (pi/2 on free resonance).
        Needs ``amplitude_m``.
    z_piezo_m : array-like, shape (n,), optional
        Piezo position [m] of each lock-in sample (larger = further from the sample).
    lockin_bandwidth_hz : float, optional
        Lock-in output bandwidth [Hz], > 0.
    amplitude2_m : array-like, shape (n,), optional
        Bimodal AM: amplitude [m], >= 0, of the second lock-in (at ``drive_frequency2_hz``,
        usually the second flexural mode). Needs ``amplitude_m``.
    phase2_rad : array-like, shape (n,), optional
        Bimodal AM: phase [rad] of the second lock-in, same lag convention as ``phase_rad``
        (pi/2 on that mode's free resonance). Needs ``amplitude2_m``.
    drive_frequency2_hz : float, optional
        Bimodal AM: the second drive frequency [Hz], > 0.
    labels : Labels, optional
        Ground truth of a simulated trace (needs ``deflection_m``).
    """

    deflection_m: FloatArray | None
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
    drive_phase_rad: float | FloatArray | None = None
    segment: NDArray[np.int8] | None = None
    amplitude_m: FloatArray | None = None
    phase_rad: FloatArray | None = None
    z_piezo_m: FloatArray | None = None
    lockin_bandwidth_hz: float | None = None
    amplitude2_m: FloatArray | None = None
    phase2_rad: FloatArray | None = None
    drive_frequency2_hz: float | None = None
    labels: Labels | None = None

    def __post_init__(self) -> None:
        if self.deflection_m is None:
            if self.amplitude_m is None:
                raise ValueError(
                    "deflection_m may be None only for lock-in curves (amplitude_m given)"
                )
            amplitude = finite_array("amplitude_m", self.amplitude_m, ndim=(1,))
            shape: tuple[int, ...] = amplitude.shape
        else:
            deflection = finite_array("deflection_m", self.deflection_m, ndim=(1, 2))
            object.__setattr__(self, "deflection_m", deflection)
            shape = deflection.shape
        checked = check_metadata(
            n_points=shape[0] if len(shape) == 2 else None,
            n_samples=shape[-1],
            **{name: getattr(self, name) for name in METADATA_FIELDS},
        )
        for name, value in checked.items():
            object.__setattr__(self, name, value)
        if self.labels is not None:
            if not isinstance(self.labels, Labels):
                raise ValueError(f"labels must be a Labels or None, got {self.labels!r}")
            if self.deflection_m is None:
                raise ValueError("labels need deflection_m (lock-in curves without a "
                                 "deflection record carry no labels)")
            self.labels.check_shape(shape)

    @property
    def has_rows(self) -> bool:
        """True when ``deflection_m`` is 2-D (a sweep or a set-point series)."""
        return self.deflection_m is not None and self.deflection_m.ndim == 2

    @property
    def is_sweep(self) -> bool:
        """True for a frequency sweep: 2-D ``deflection_m`` with one drive frequency per row."""
        return self.has_rows and np.ndim(self.drive_frequency_hz) == 1

    @property
    def is_series(self) -> bool:
        """True for a set-point series: 2-D ``deflection_m`` with one rest gap per row."""
        return self.has_rows and np.shape(self.gap_m) == (self.n_points,)

    @property
    def is_ramp(self) -> bool:
        """True for a 1-D record whose rest gap varies in time (``gap_m`` of shape (n,))."""
        return not self.has_rows and np.ndim(self.gap_m) == 1

    @property
    def is_curves(self) -> bool:
        """True for lock-in curves (``amplitude_m`` present)."""
        return self.amplitude_m is not None

    @property
    def n_samples(self) -> int:
        """Number of samples n per row."""
        if self.deflection_m is None:
            assert self.amplitude_m is not None
            return self.amplitude_m.shape[0]
        return self.deflection_m.shape[-1]

    @property
    def n_points(self) -> int:
        """Number of rows of a sweep or series; 1 for a single trace."""
        return self.deflection_m.shape[0] if self.has_rows else 1  # type: ignore[union-attr]

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

    def row(self, i: int) -> Trace:
        """Row ``i`` as a 1-D trace with its own gap, drive frequency, drive phase and labels.

        Parameters
        ----------
        i : int
            Row index, 0 <= i < n_points. For a trace without rows, ``row(0)`` is the trace.

        Returns
        -------
        Trace
            ``deflection_m`` of shape (n,); ``gap_m``, ``drive_frequency_hz`` and
            ``drive_phase_rad`` of that row; labels reduced to that row (per-row scalars to
            the row's value).
        """
        index = row_index(i, self.n_points)
        if not self.has_rows:
            return self
        assert self.deflection_m is not None
        labels = None if self.labels is None else self.labels.row(index)
        return Trace(
            self.deflection_m[index],
            **row_metadata(self.metadata(), index, self.n_points),
            labels=labels,
        )


METADATA_FIELDS: tuple[str, ...] = tuple(
    f.name for f in fields(Trace) if f.name not in ("deflection_m", "labels", "_")
)


def row_index(i: Any, n_points: int) -> int:
    """Return ``i`` as an int in [0, n_points); raise ``ValueError`` otherwise."""
    if isinstance(i, bool) or not isinstance(i, int | np.integer):
        raise ValueError(f"i must be an integer in [0, {n_points}), got {i!r}")
    if not 0 <= i < n_points:
        raise ValueError(f"i must be in [0, {n_points}), got {i}")
    return int(i)


def row_metadata(metadata: dict[str, Any], i: int, n_points: int) -> dict[str, Any]:
    """Metadata of row ``i`` of a 2-D trace: per-row fields reduced to their row's value.

    Parameters
    ----------
    metadata : dict
        Validated metadata of a trace with ``n_points`` rows (see `check_metadata`).
    i : int
        Row index.
    n_points : int
        Number of rows.
    """
    out = dict(metadata)
    for name in _PER_ROW:
        value = out.get(name)
        if isinstance(value, np.ndarray) and value.shape == (n_points,):
            out[name] = float(value[i])
    return out


def _per_row_or_number(
    name: str, value: Any, *, n_points: int | None, positive_values: bool = False
) -> float | FloatArray:
    """A number, or (for 2-D traces only) an array of shape (n_points,)."""
    if np.ndim(value) == 0:
        return positive(name, value) if positive_values else finite_number(name, value)
    if n_points is None or np.shape(value) != (n_points,):
        allowed = "a single number" if n_points is None else (
            f"a number or an array of shape (n_points,) = ({n_points},)"
        )
        raise ValueError(f"{name} must be {allowed}, got shape {np.shape(value)}")
    return finite_array(name, value, ndim=(1,), positive=positive_values)


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
    drive_phase_rad: Any = None,
    segment: Any = None,
    amplitude_m: Any = None,
    phase_rad: Any = None,
    z_piezo_m: Any = None,
    lockin_bandwidth_hz: Any = None,
    amplitude2_m: Any = None,
    phase2_rad: Any = None,
    drive_frequency2_hz: Any = None,
) -> dict[str, Any]:
    """Validate the metadata of a trace with ``n_points`` rows (None: 1-D) of ``n_samples``.

    Returns the normalised values keyed by field name; raises ``ValueError`` naming the field.
    """
    if n_points is None:
        if np.ndim(drive_frequency_hz) != 0:
            raise ValueError(
                "drive_frequency_hz must be a single number when deflection_m is 1-D, "
                f"got shape {np.shape(drive_frequency_hz)}"
            )
    elif np.ndim(drive_frequency_hz) != 0 and np.shape(drive_frequency_hz) != (n_points,):
        raise ValueError(
            "drive_frequency_hz must be an array of shape (n_points,) = "
            f"({n_points},) when deflection_m is 2-D (a sweep), "
            f"got shape {np.shape(drive_frequency_hz)}"
        )
    drive = _per_row_or_number(
        "drive_frequency_hz", drive_frequency_hz, n_points=n_points, positive_values=True
    )
    gap = _check_gap(gap_m, n_points=n_points, n_samples=n_samples)
    if n_points is not None and np.ndim(drive) == 0 and np.shape(gap) != (n_points,):
        raise ValueError(
            f"drive_frequency_hz must be an array of shape (n_points,) = ({n_points},) when "
            "deflection_m is 2-D (a sweep), unless gap_m has that shape (a set-point series); "
            f"got shape {np.shape(drive)} with gap_m of shape {np.shape(gap)}"
        )
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
    phase = (
        None
        if drive_phase_rad is None
        else _per_row_or_number("drive_phase_rad", drive_phase_rad, n_points=n_points)
    )
    lockin = _check_lockin(
        n_points=n_points,
        n_samples=n_samples,
        segment=segment,
        amplitude_m=amplitude_m,
        phase_rad=phase_rad,
        z_piezo_m=z_piezo_m,
        amplitude2_m=amplitude2_m,
        phase2_rad=phase2_rad,
    )
    if drive_frequency2_hz is not None and lockin["amplitude2_m"] is None:
        raise ValueError("drive_frequency2_hz needs amplitude2_m (a bimodal lock-in curve)")
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
        "drive_phase_rad": phase,
        **lockin,
        "lockin_bandwidth_hz": optional_positive("lockin_bandwidth_hz", lockin_bandwidth_hz),
        "drive_frequency2_hz": optional_positive("drive_frequency2_hz", drive_frequency2_hz),
    }


def _check_gap(gap_m: Any, *, n_points: int | None, n_samples: int) -> float | FloatArray:
    if np.ndim(gap_m) == 0:
        return finite_number("gap_m", gap_m)
    allowed = [(n_samples,)] if n_points is None else [(n_points,), (n_samples,)]
    if np.shape(gap_m) not in allowed:
        shapes = f"(n,) = ({n_samples},)"
        if n_points is not None:
            shapes = f"(n_points,) = ({n_points},) (a set-point series) or " + shapes
        raise ValueError(
            f"gap_m must be a number or an array of shape {shapes}, got shape {np.shape(gap_m)}"
        )
    return finite_array("gap_m", gap_m, ndim=(1,))


def _check_lockin(
    *,
    n_points: int | None,
    n_samples: int,
    segment: Any,
    amplitude_m: Any,
    phase_rad: Any,
    z_piezo_m: Any,
    amplitude2_m: Any = None,
    phase2_rad: Any = None,
) -> dict[str, Any]:
    """Validate ``segment`` and the lock-in arrays: 1-D traces only, shape (n,) each."""
    given = {"segment": segment, "amplitude_m": amplitude_m, "phase_rad": phase_rad,
             "z_piezo_m": z_piezo_m, "amplitude2_m": amplitude2_m, "phase2_rad": phase2_rad}
    out: dict[str, Any] = dict.fromkeys(given)
    for name, value in given.items():
        if value is None:
            continue
        if n_points is not None:
            raise ValueError(
                f"{name} is allowed only with a 1-D deflection_m (ramps and curves), "
                f"but deflection_m has {n_points} rows"
            )
        if name == "segment":
            out[name] = segment_array(name, value, n_samples)
        else:
            out[name] = finite_array(name, value, ndim=(1,), shape=(n_samples,))
    if out["phase_rad"] is not None and out["amplitude_m"] is None:
        raise ValueError("phase_rad needs amplitude_m (lock-in curves give both)")
    if out["phase2_rad"] is not None and out["amplitude2_m"] is None:
        raise ValueError("phase2_rad needs amplitude2_m (a bimodal lock-in gives both)")
    if out["amplitude2_m"] is not None and out["amplitude_m"] is None:
        raise ValueError("amplitude2_m needs amplitude_m (the second lock-in of a bimodal curve)")
    for name in ("amplitude_m", "amplitude2_m"):
        if out[name] is not None and np.any(out[name] < 0):
            raise ValueError(f"{name} must be >= 0, found min {out[name].min()!r}")
    return out
