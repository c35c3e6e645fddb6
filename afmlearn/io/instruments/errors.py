"""The error raised for instrument files that cannot be read or calibrated."""

from __future__ import annotations

__all__ = ["RecordingError"]


class RecordingError(ValueError):
    """An instrument file is unknown, damaged, lacks calibration or has the wrong units.

    The message is one line naming the file and what to do, e.g. ``"x.csv: missing
    calibration 'spring_constant_n_per_m': pass spring_constant_n_per_m=... or
    calibration=calibration.json"``.
    """
