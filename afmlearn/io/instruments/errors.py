"""The error raised for instrument files that cannot be read or calibrated."""

from __future__ import annotations

__all__ = ["RecordingError", "MissingCalibration"]


class RecordingError(ValueError):
    """An instrument file is unknown, damaged, lacks calibration or has the wrong units.

    The message is one line naming the file and what to do, e.g. ``"x.csv: missing
    calibration 'spring_constant_n_per_m' (not in the file): pass spring_constant_n_per_m=VALUE
    or calibration=calibration.json (scripts/calibrate.py)"``.
    """


class MissingCalibration(RecordingError):
    """A calibration field the recording needs is in neither the file, calibration.json nor
    the overrides; ``field`` names it."""

    def __init__(self, message: str, *, field: str) -> None:
        super().__init__(message)
        self.field = field
