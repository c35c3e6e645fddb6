"""`ForceCurve`: a static force-distance curve (no drive), and its HDF5 file.

A static curve has no drive frequency, so the trace format's required
``drive_frequency_hz`` cannot be filled honestly: static curves are this small object and
their own file kind (``format = "afmlearn-forcecurve"``, version 1; docs/recordings.md).
"""

from __future__ import annotations

import os
from dataclasses import KW_ONLY, dataclass
from pathlib import Path
from typing import Any, final

import h5py
import numpy as np
from numpy.typing import NDArray

from afmlearn.io._atomic import atomic_path
from afmlearn.io._checks import finite_array, optional_positive, segment_array
from afmlearn.io.instruments.errors import RecordingError

__all__ = ["FORCE_CURVE_FORMAT", "ForceCurve", "read_force_curve", "write_force_curve"]

FORCE_CURVE_FORMAT = "afmlearn-forcecurve"
_ARRAYS = ("force_n", "deflection_m", "z_piezo_m", "segment", "time_s")
_SCALARS = ("spring_constant_n_per_m", "sample_rate_hz", "invols_m_per_v",
            "resonance_frequency_hz", "quality_factor")


@final
@dataclass(frozen=True, eq=False)
class ForceCurve:
    """One static approach/retract curve in SI units.

    Parameters
    ----------
    force_n : array-like, shape (n,)
        Tip-sample force [N], > 0 repulsive (pushes the tip away from the sample).
    z_piezo_m : array-like, shape (n,)
        Piezo position [m], larger = further from the sample (offset arbitrary).
    segment : array-like of int, shape (n,)
        ``0`` approach, ``1`` retraction.
    deflection_m : array-like, shape (n,), optional
        Static deflection [m], towards the sample positive (``-force_n / k``); None when the
        spring constant is unknown.
    spring_constant_n_per_m : float, optional
        k [N/m], > 0.
    sample_rate_hz : float, optional
        Points per second [Hz], > 0.
    time_s : array-like, shape (n,), optional
        Time of each point [s].
    invols_m_per_v : float, optional
        Deflection sensitivity of the optical lever [m/V].
    resonance_frequency_hz, quality_factor : float, optional
        The lever's thermal f0 [Hz] and Q, when the file states them.
    description : str
        Where the curve comes from.
    """

    force_n: NDArray[np.float64]
    _: KW_ONLY
    z_piezo_m: NDArray[np.float64]
    segment: NDArray[np.int8]
    deflection_m: NDArray[np.float64] | None = None
    spring_constant_n_per_m: float | None = None
    sample_rate_hz: float | None = None
    time_s: NDArray[np.float64] | None = None
    invols_m_per_v: float | None = None
    resonance_frequency_hz: float | None = None
    quality_factor: float | None = None
    description: str = ""

    def __post_init__(self) -> None:
        force = finite_array("force_n", self.force_n, ndim=(1,))
        n = force.size
        set_ = object.__setattr__
        set_(self, "force_n", force)
        for name in ("z_piezo_m", "deflection_m", "time_s"):
            value = getattr(self, name)
            if value is None:
                continue
            arr = finite_array(name, value, ndim=(1,))
            if arr.size != n:
                raise ValueError(f"{name} must have shape ({n},) like force_n, got {arr.shape}")
            set_(self, name, arr)
        set_(self, "segment", segment_array("segment", self.segment, n))
        for name in _SCALARS:
            set_(self, name, optional_positive(name, getattr(self, name)))

    @property
    def n_points(self) -> int:
        """Number of points n."""
        return self.force_n.size


def write_force_curve(curve: ForceCurve, path: str | os.PathLike[str]) -> Path:
    """Write ``curve`` atomically as an ``afmlearn-forcecurve`` HDF5 file; returns the path."""
    path = Path(path)
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        f.attrs["format"] = FORCE_CURVE_FORMAT
        f.attrs["format_version"] = 1
        f.attrs["description"] = curve.description
        for name in _SCALARS:
            if getattr(curve, name) is not None:
                f.attrs[name] = getattr(curve, name)
        for name in _ARRAYS:
            if getattr(curve, name) is not None:
                f.create_dataset(name, data=getattr(curve, name))
    return path


def read_force_curve(path: str | os.PathLike[str]) -> ForceCurve:
    """Read an ``afmlearn-forcecurve`` file written by `write_force_curve`."""
    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("format") != FORCE_CURVE_FORMAT:
                raise RecordingError(f"{path}: not an {FORCE_CURVE_FORMAT} file")
            kwargs: dict[str, Any] = {n: f[n][()] for n in _ARRAYS if n in f}
            kwargs.update({n: float(f.attrs[n]) for n in _SCALARS if n in f.attrs})
            kwargs["description"] = str(f.attrs.get("description", ""))
    except OSError as err:
        raise RecordingError(f"{path}: not a readable HDF5 file ({err})") from None
    try:
        return ForceCurve(**kwargs)
    except (TypeError, ValueError) as err:
        raise RecordingError(f"{path}: {err}") from None
