"""Input checks for analyses of recorded traces: refuse data that cannot be analysed.

What `afmlearn.io` already guarantees (and is not repeated here): a `Trace` cannot hold
NaN/inf deflection, non-positive ``sample_rate_hz``, ``spring_constant_n_per_m``,
``quality_factor``, ``resonance_frequency_hz`` or drive frequency, and ``read_trace`` raises
`afmlearn.io.TraceFormatError` (a ``ValueError``) for a file that misses a required attribute
or holds NaN. `check_trace` adds what the format allows but an analysis cannot use: a
non-positive rest gap, too few samples per drive period, too few periods, a clipped
(saturated) signal. `check_deflection` runs the sample-level checks on a bare array (NaN
included), for data that do not come through a `Trace`.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from afmlearn.io import Trace

__all__ = [
    "checked_row",
    "CalibrationError",
    "ClippedSignalError",
    "InputError",
    "NonFiniteError",
    "TooShortError",
    "UndersampledError",
    "check_deflection",
    "check_trace",
    "clipped_run",
]

#: relative tolerance (of the signal range) for "equal to the extreme value"
CLIP_RTOL = 1e-12
#: a run at an extreme longer than this many times what a smooth quantised peak gives is
#: clipping; together with `MIN_CLIP_FRACTION` of a period and `MIN_CLIP_SAMPLES` samples
CLIP_FACTOR = 3.0
MIN_CLIP_FRACTION = 0.01
MIN_CLIP_SAMPLES = 4


class InputError(ValueError):
    """A trace that cannot be analysed; the message says why and what is needed."""


class NonFiniteError(InputError):
    """NaN or inf in the deflection."""


class UndersampledError(InputError):
    """Fewer samples per drive period than the analysis needs."""


class TooShortError(InputError):
    """Fewer drive periods than the analysis needs."""


class ClippedSignalError(InputError):
    """The signal is saturated (flat runs at its extreme values)."""


class CalibrationError(InputError):
    """Missing or non-physical calibration."""


def check_trace(trace: Trace, *, row: int | None = None, min_samples_per_period: float = 20.0,
                min_periods: float = 3.0) -> None:
    """Raise an `InputError` subclass if ``trace`` cannot be analysed.

    Parameters
    ----------
    trace : afmlearn.io.Trace
        The recording (labels are never looked at).
    row : int, optional
        Check only this row of a sweep; None checks every row.
    min_samples_per_period : float, default 20
        Required samples per drive period (``sample_rate / f_drive``).
    min_periods : float, default 3
        Required number of drive periods per row.

    Raises
    ------
    CalibrationError
        Non-positive rest gap (``gap_m`` <= 0 anywhere), or not a `Trace`.
    UndersampledError, TooShortError, ClippedSignalError, NonFiniteError
        See `check_deflection`.
    """
    if not isinstance(trace, Trace):
        raise CalibrationError(f"trace must be an afmlearn.io.Trace, got "
                               f"{type(trace).__name__}")
    gap = np.asarray(trace.gap_m)
    if np.any(gap <= 0):
        raise CalibrationError(f"gap_m (rest tip-sample gap) must be > 0 everywhere, found "
                               f"min {float(gap.min())!r} m")
    rows = range(trace.n_points) if row is None else [row]
    for r in rows:
        if trace.has_rows:
            if isinstance(r, bool) or not isinstance(r, int | np.integer) \
                    or not 0 <= r < trace.n_points:
                raise ValueError(f"row must be an integer in [0, {trace.n_points}), got {r!r}")
            x, f = trace.deflection_m[r], float(np.atleast_1d(trace.drive_frequency_hz)[
                r if np.ndim(trace.drive_frequency_hz) else 0])
            where = f"row {r}: "
        else:
            if r not in (None, 0):
                raise ValueError(f"row must be None (or 0) for a single trace, got {r!r}")
            x, f = trace.deflection_m, float(trace.drive_frequency_hz)
            where = ""
        try:
            check_deflection(x, samples_per_period=trace.sample_rate_hz / f,
                             min_samples_per_period=min_samples_per_period,
                             min_periods=min_periods)
        except UndersampledError:
            # with the rate it takes at this drive frequency
            raise UndersampledError(where + _undersampled_text(
                trace.sample_rate_hz / f, min_samples_per_period,
                rates=(trace.sample_rate_hz, f))) from None
        except InputError as err:
            raise type(err)(where + str(err)) from None


def check_deflection(x: ArrayLike, *, samples_per_period: float,
                     min_samples_per_period: float = 20.0, min_periods: float = 3.0) -> None:
    """Sample-level checks of one deflection row.

    Parameters
    ----------
    x : array-like, shape (n,)
        Deflection (any unit).
    samples_per_period : float
        ``sample_rate / f_drive``.
    min_samples_per_period, min_periods : float
        As in `check_trace`.

    Raises
    ------
    NonFiniteError
        NaN/inf samples.
    UndersampledError
        ``samples_per_period < min_samples_per_period``.
    TooShortError
        Fewer than ``min_periods`` drive periods.
    ClippedSignalError
        A clipped signal, see `clipped_run`.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"x must be 1-D, got shape {x.shape}")
    n_bad = int(np.count_nonzero(~np.isfinite(x)))
    if n_bad:
        raise NonFiniteError(f"deflection holds {n_bad} NaN/inf sample(s); remove or "
                             "interpolate them before the analysis")
    if not (math.isfinite(samples_per_period) and samples_per_period > 0):
        raise CalibrationError(f"samples_per_period must be > 0, got {samples_per_period!r}")
    if samples_per_period < min_samples_per_period:
        raise UndersampledError(_undersampled_text(samples_per_period,
                                                   min_samples_per_period))
    periods = x.size / samples_per_period
    if periods < min_periods:
        raise TooShortError(f"the deflection spans {periods:.3g} drive periods; at least "
                            f"{min_periods:g} are needed")
    run, limit = clipped_run(x, samples_per_period=samples_per_period)
    if run > limit:
        raise ClippedSignalError(
            f"the deflection looks clipped (saturated): {run} consecutive samples sit at its "
            f"extreme value, a smooth peak allows at most {limit:.1f}; check the detector "
            "range and gain")


def _undersampled_text(samples_per_period: float, min_samples_per_period: float, *,
                       rates: tuple[float, float] | None = None) -> str:
    """Why an undersampled row is refused and what to do: a recording cannot be fixed by
    resampling (the harmonics above its Nyquist frequency were never sampled), a simulation
    by its ``scenario.samples_per_period``. ``rates``: (sample rate, drive frequency) [Hz]."""
    txt = f"only {samples_per_period:.3g} samples per drive period"
    need = f"at least {min_samples_per_period:g} are needed"
    if rates is not None:
        rate, f = rates
        txt += f" (sample_rate_hz {rate:.4g} Hz at a drive frequency of {f:.4g} Hz)"
        need += f", i.e. a sample rate of at least {min_samples_per_period * f:.4g} Hz"
    return (f"{txt}; {need}: record at a higher sample rate (resampling a recording cannot "
            "restore the harmonics it did not sample); for a simulation raise "
            "scenario.samples_per_period")


def clipped_run(x: ArrayLike, *, samples_per_period: float) -> tuple[int, float]:
    """Longest run of samples at the signal's max or min, and the run length allowed.

    Parameters
    ----------
    x : array-like, shape (n,)
        Deflection.
    samples_per_period : float
        Samples per drive period.

    Returns
    -------
    run : int
        Longest run of consecutive samples within ``1e-12 * range`` of ``max(x)`` or
        ``min(x)``.
    limit : float
        Longest run a smooth, unclipped but quantised peak can produce:
        ``max(MIN_CLIP_SAMPLES, MIN_CLIP_FRACTION * spp, CLIP_FACTOR * L_q)`` with
        ``L_q = spp / pi * sqrt(2 q / A)`` the number of samples a sinusoid of amplitude
        ``A = range / 2`` spends within one quantisation step ``q`` of its peak
        (``A (1 - cos phi) <= q``). ``q`` is the median spacing of the distinct sample values
        (the ADC step for quantised data, ~0 for floating-point data).

    Notes
    -----
    A 16-bit quantised sinusoid at 1500 samples per period gives runs of ~4 samples (limit
    ~15); a sinusoid clipped at 95 % of its amplitude sits at the clip level for 10 % of each
    period (150 samples).
    """
    x = np.asarray(x, dtype=float)
    lo, hi = float(x.min()), float(x.max())
    span = hi - lo
    floor = max(float(MIN_CLIP_SAMPLES), MIN_CLIP_FRACTION * samples_per_period)
    if span <= 0:
        return x.size, floor  # a constant signal: one long run
    tol = CLIP_RTOL * span
    run = max(_longest_run(x >= hi - tol), _longest_run(x <= lo + tol))
    levels = np.unique(x)
    q = float(np.median(np.diff(levels))) if levels.size > 1 else span
    smooth = samples_per_period / math.pi * math.sqrt(2.0 * q / (0.5 * span))
    return run, max(floor, CLIP_FACTOR * smooth)


def _longest_run(mask: np.ndarray) -> int:
    """Length of the longest run of True in a 1-D boolean array."""
    if not mask.any():
        return 0
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    d = np.diff(padded)
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return int((ends - starts).max())


def checked_row(trace: Trace, row: int | None) -> int | None:
    """``row`` validated for ``trace``: required (in range) for a sweep, optional for a set-point
    series (None: every row, jointly), None for a single trace."""
    if trace.has_rows:
        if row is None:
            if trace.is_series:
                return None
            raise ValueError(f"row: the trace is a sweep of {trace.n_points} rows; pass row=<i> "
                             f"with i in [0, {trace.n_points}) to choose the drive frequency")
        if isinstance(row, bool) or not isinstance(row, int | np.integer) \
                or not 0 <= int(row) < trace.n_points:
            raise ValueError(f"row must be an integer in [0, {trace.n_points}), got {row!r}")
        return int(row)
    if row is not None:
        raise ValueError(f"row must be null for a single (non-sweep) trace, got {row!r}")
    return None
