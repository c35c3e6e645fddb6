"""`Trace` and `Labels`: validation on construction and derived properties."""

from __future__ import annotations

from dataclasses import FrozenInstanceError
from typing import Any

import numpy as np
import pytest

from afmlearn.io import Labels, Trace


def make(calibration: dict[str, Any], **changes: Any) -> Trace:
    kwargs = {"drive_frequency_hz": 3e5, "gap_m": 1e-8, **calibration, **changes}
    deflection = kwargs.pop("deflection_m", np.zeros(100))
    return Trace(deflection, **kwargs)


def test_properties(calibration: dict[str, Any]) -> None:
    trace = make(calibration)
    assert not trace.is_sweep
    assert (trace.n_points, trace.n_samples) == (1, 100)
    assert trace.dt_s == pytest.approx(2e-7)
    np.testing.assert_allclose(trace.time_s[:3], [0.0, 2e-7, 4e-7])
    sweep = make(calibration, deflection_m=np.zeros((3, 50)), drive_frequency_hz=[1e5, 2e5, 3e5])
    assert sweep.is_sweep and (sweep.n_points, sweep.n_samples) == (3, 50)


def test_frozen_and_read_only(calibration: dict[str, Any]) -> None:
    data = np.zeros(100)
    trace = make(calibration, deflection_m=data)
    with pytest.raises(FrozenInstanceError):
        trace.quality_factor = 1.0  # type: ignore[misc]
    with pytest.raises(ValueError):
        trace.deflection_m[0] = 1.0
    data[0] = 1.0  # the caller's array stays writeable


@pytest.mark.parametrize(
    ("changes", "name"),
    [
        ({"sample_rate_hz": 0.0}, "sample_rate_hz"),
        ({"spring_constant_n_per_m": -1.0}, "spring_constant_n_per_m"),
        ({"quality_factor": np.inf}, "quality_factor"),
        ({"resonance_frequency_hz": np.nan}, "resonance_frequency_hz"),
        ({"resonance_frequency_hz": "3e5"}, "resonance_frequency_hz"),
        ({"drive_frequency_hz": [3e5, 3e5]}, "drive_frequency_hz"),
        ({"gap_m": np.nan}, "gap_m"),
        ({"gap_m": np.zeros(99)}, "gap_m"),
        ({"deflection_m": np.zeros((2, 3, 4))}, "deflection_m"),
        ({"deflection_m": np.array([0.0, np.nan])}, "deflection_m"),
        ({"deflection_m": np.zeros((2, 5))}, "drive_frequency_hz"),
        (
            {"deflection_m": np.zeros((2, 5)), "drive_frequency_hz": [1e5, 2e5, 3e5]},
            "drive_frequency_hz",
        ),
        ({"excitation": "side"}, "excitation"),
        ({"dither_amplitude_m": 0.0}, "dither_amplitude_m"),
        ({"free_amplitude_m": -1e-9}, "free_amplitude_m"),
        ({"tip_radius_m": 0}, "tip_radius_m"),
        ({"higher_mode_frequencies_hz": [2e6, -1.0]}, "higher_mode_frequencies_hz"),
        ({"free_deflection_m": np.zeros((2, 2))}, "free_deflection_m"),
        ({"description": 3}, "description"),
        ({"labels": Labels(np.zeros(99))}, "labels.force_n"),
        ({"labels": Labels(np.zeros(100), modal_m=np.zeros((2, 99)))}, "labels.modal_m"),
        ({"labels": Labels(np.zeros(100), scalars={"e_j": np.ones(3)})}, "labels.scalars"),
    ],
)
def test_bad_input_names_the_field(
    calibration: dict[str, Any], changes: dict[str, Any], name: str
) -> None:
    with pytest.raises(ValueError, match=name.replace(".", r"\.")):
        make(calibration, **changes)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"model": {"bad": object()}}, "labels.model"),
        ({"model": {"x": float("nan")}}, "labels.model"),
        ({"effect": ""}, "labels.effect"),
        ({"scalars": {"a/b": 1.0}}, "labels.scalars"),
        ({"scalars": {"force_n": 1.0}}, "labels.scalars"),
        ({"scalars": {"e_j": np.nan}}, "labels.scalars"),
        ({"extra": {"z": np.array([np.inf])}}, "labels.extra"),
    ],
)
def test_bad_labels(kwargs: dict[str, Any], name: str) -> None:
    with pytest.raises(ValueError, match=name.replace(".", r"\.")):
        Labels(np.zeros(10), **kwargs)


def test_sweep_accepts_per_row_scalars(calibration: dict[str, Any]) -> None:
    labels = Labels(np.zeros((3, 5)), scalars={"e_j": [1.0, 2.0, 3.0], "c": 0.5})
    trace = make(
        calibration,
        deflection_m=np.zeros((3, 5)),
        drive_frequency_hz=[1e5, 2e5, 3e5],
        labels=labels,
    )
    assert trace.labels is labels
    assert trace.labels.scalars["c"] == 0.5
