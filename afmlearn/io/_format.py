"""Names fixed by the trace file format, version 1 (design.md section 2)."""

from __future__ import annotations

from typing import Final

FORMAT: Final = "afmlearn-trace"
FORMAT_VERSION: Final = 1
SUPPORTED_VERSIONS: Final = (1,)

#: Required root attributes that must be attributes.
REQUIRED_ATTRS: Final = (
    "sample_rate_hz",
    "spring_constant_n_per_m",
    "quality_factor",
    "resonance_frequency_hz",
)
#: Required entries that are an attribute (a number) or a dataset (an array).
ATTR_OR_DATASET: Final = ("drive_frequency_hz", "gap_m")
#: Optional entries that are an attribute (a number) or a dataset (one value per row).
OPTIONAL_ATTR_OR_DATASET: Final = ("drive_phase_rad",)
#: Optional entries that are datasets (``segment`` is int8; the lock-in curves are float64).
OPTIONAL_DATASETS: Final = ("free_deflection_m", "segment", "amplitude_m", "phase_rad", "z_piezo_m",
                             "amplitude2_m", "phase2_rad")
#: Datasets whose presence makes ``deflection_m`` optional (lock-in curves).
LOCKIN_AMPLITUDE: Final = "amplitude_m"

DEFLECTION: Final = "deflection_m"
DRIVE_PHASE: Final = "drive_phase_rad"
LABELS_GROUP: Final = "labels"
LABELS_ARRAYS: Final = ("force_n", "modal_m")
LABELS_ATTRS: Final = ("model", "effect")
EXTRA_GROUP: Final = "extra"
