"""The error raised for trace files and dataset folders that break the format contract."""

from __future__ import annotations

__all__ = ["TraceFormatError"]


class TraceFormatError(ValueError):
    """A trace file or dataset folder does not follow the afmlearn trace format.

    The message names the file, the offending attribute or dataset, what was expected and
    what was found, e.g. ``"run.h5: dataset 'deflection_m' must have shape (n,) or
    (n_points, n), found shape (2, 3, 4)"``.
    """
