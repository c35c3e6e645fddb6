"""Preprocessing of recorded traces: checks, calibration, periodic denoising, derivatives.

Public API
----------
`check_trace`, `check_deflection`, `InputError` (and subclasses)
    Refuse traces that cannot be analysed (clipped, undersampled, too short, NaN, bad gap).
`calibrate`, `Calibrated`
    The dimensionless view of one trace row, with the drive amplitude ``F_c`` from free data.
`fit_harmonics`, `HarmonicFit`, `phase_average`
    Least-squares Fourier series in the drive phase over all samples; analytic derivatives.
`afmlearn.preprocess.phase`: `align_phase`, `wrap_angle`
    The drive phase of a steady orbit in closed form from its harmonics (output-error fits).
`savgol_derivatives`, `spectral_derivatives`, `SavitzkyGolay`, `Spectral`,
`HarmonicDerivatives`, `AbstractDerivatives`, `default_window`
    Derivative estimators (functions and strategy objects).
"""

from afmlearn.preprocess.calibration import Calibrated, calibrate, free_drive_amplitude
from afmlearn.preprocess.checks import (
    CalibrationError,
    ClippedSignalError,
    InputError,
    NonFiniteError,
    TooShortError,
    UndersampledError,
    check_deflection,
    check_trace,
    checked_row,
    clipped_run,
)
from afmlearn.preprocess.derivatives import (
    AbstractDerivatives,
    HarmonicDerivatives,
    SavitzkyGolay,
    Spectral,
    default_window,
    savgol_derivatives,
    spectral_derivatives,
)
from afmlearn.preprocess.harmonics import HarmonicFit, fit_harmonics, phase_average

__all__ = [
    "AbstractDerivatives",
    "Calibrated",
    "CalibrationError",
    "ClippedSignalError",
    "HarmonicDerivatives",
    "HarmonicFit",
    "InputError",
    "NonFiniteError",
    "SavitzkyGolay",
    "Spectral",
    "TooShortError",
    "UndersampledError",
    "calibrate",
    "check_deflection",
    "check_trace",
    "checked_row",
    "clipped_run",
    "default_window",
    "fit_harmonics",
    "free_drive_amplitude",
    "phase_average",
    "savgol_derivatives",
    "spectral_derivatives",
]
