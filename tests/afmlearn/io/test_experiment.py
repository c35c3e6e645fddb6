"""`Experiment`: shared calibration, kinds, subsets, reading without the labels."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from afmlearn.io import Experiment, Labels, Trace, write_trace

N = 32


def steady(calibration: dict[str, Any], gap: float, **changes: Any) -> Trace:
    kwargs = {"drive_frequency_hz": 3e5, "gap_m": gap, **calibration, **changes}
    return Trace(np.full(N, gap), **kwargs)


def series_trace(calibration: dict[str, Any], *, labels: bool = True) -> Trace:
    gaps = np.array([8e-9, 6e-9, 4e-9])
    truth = Labels(np.ones((3, N)) * gaps[:, None], model={"name": "dmt"},
                   scalars={"dissipated_energy_j": gaps * 1e-10}) if labels else None
    return Trace(np.ones((3, N)) * gaps[:, None], **calibration, drive_frequency_hz=3e5,
                 gap_m=gaps, drive_phase_rad=np.array([0.1, 0.2, 0.3]), labels=truth)


def test_from_series_one_observation_per_row(calibration: dict[str, Any]) -> None:
    trace = series_trace(calibration)
    exp = Experiment.from_trace(trace)
    assert exp.kind == "series" and len(exp) == 3
    np.testing.assert_array_equal(exp.gaps_m, trace.gap_m)
    np.testing.assert_array_equal(exp.drive_phases_rad, [0.1, 0.2, 0.3])
    for i, obs in enumerate(exp):
        np.testing.assert_array_equal(obs.deflection_m, trace.deflection_m[i])  # type: ignore
        assert obs.labels is not None
        assert obs.labels.scalars["dissipated_energy_j"] == pytest.approx(exp.gaps_m[i] * 1e-10)
    assert exp[-1] is exp.observations[2]
    assert exp.calibration == {**calibration, "excitation": None}


def test_from_sweep_single_ramp_and_curves(calibration: dict[str, Any]) -> None:
    sweep = Trace(np.zeros((4, N)), **calibration, drive_frequency_hz=[1e5, 2e5, 3e5, 4e5],
                  gap_m=5e-9)
    exp = Experiment.from_trace(sweep)
    assert exp.kind == "sweep" and len(exp) == 4
    np.testing.assert_array_equal(exp.drive_frequencies_hz, sweep.drive_frequency_hz)
    np.testing.assert_array_equal(exp.gaps_m, np.full(4, 5e-9))
    assert np.all(np.isnan(exp.drive_phases_rad))
    single = steady(calibration, 5e-9, drive_phase_rad=1.0)
    one = Experiment.from_trace(single)
    assert one.kind == "single" and len(one) == 1 and one[0] is single
    assert one.drive_phases_rad.tolist() == [1.0]
    ramp = Trace(np.zeros(N), **calibration, drive_frequency_hz=3e5,
                 gap_m=np.linspace(9e-9, 1e-9, N))
    exp = Experiment.from_trace(ramp)
    assert exp.kind == "ramp" and np.isnan(exp.gaps_m).all()
    curves = Trace(None, **calibration, drive_frequency_hz=3e5, gap_m=2e-9,
                   amplitude_m=np.ones(N), z_piezo_m=np.linspace(0, 1e-8, N))
    assert Experiment.from_trace(curves).kind == "curves"


def test_kind_is_inferred_from_the_observations(calibration: dict[str, Any]) -> None:
    a, b = steady(calibration, 6e-9), steady(calibration, 4e-9)
    assert Experiment([a, b]).kind == "series"
    c = steady(calibration, 4e-9, drive_frequency_hz=2.9e5)
    assert Experiment([a, c]).kind == "sweep"
    assert Experiment([a]).kind == "single"
    with pytest.raises(ValueError, match="kind must be one of"):
        Experiment([a], kind="movie")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("sample_rate_hz", 4e6),
        ("spring_constant_n_per_m", 41.0),
        ("quality_factor", 401.0),
        ("resonance_frequency_hz", 3.1e5),
        ("excitation", "base"),
    ],
)
def test_shared_calibration_is_checked(calibration: dict[str, Any], name: str,
                                       value: Any) -> None:
    a = steady(calibration, 6e-9)
    b = steady(calibration, 4e-9, **{name: value})
    with pytest.raises(ValueError, match=rf"{name} must be the same .* observations\[1\]"):
        Experiment([a, a, b][1:])


def test_bad_observations(calibration: dict[str, Any]) -> None:
    a = steady(calibration, 6e-9)
    with pytest.raises(ValueError, match="at least one"):
        Experiment([])
    with pytest.raises(ValueError, match="from_trace"):
        Experiment(a)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"observations\[1\] must be an afmlearn.io.Trace"):
        Experiment([a, np.zeros(N)])  # type: ignore[list-item]
    with pytest.raises(ValueError, match=r"observations\[0\] has 3 rows"):
        Experiment([series_trace(calibration)])


def test_subset_for_leave_one_out(calibration: dict[str, Any]) -> None:
    exp = Experiment.from_trace(series_trace(calibration))
    for held in range(len(exp)):
        rest = exp.subset([i for i in range(len(exp)) if i != held])
        assert len(rest) == 2 and rest.kind == "series"
        assert exp.gaps_m[held] not in rest.gaps_m
    np.testing.assert_array_equal(exp.subset([2, 0]).gaps_m, exp.gaps_m[[2, 0]])
    np.testing.assert_array_equal(exp[1:].gaps_m, exp.gaps_m[1:])
    with pytest.raises(ValueError, match="distinct"):
        exp.subset([0, 0])
    with pytest.raises(ValueError, match="at least one"):
        exp.subset([])
    with pytest.raises(ValueError, match=r"index must be in \[-3, 3\)"):
        exp.subset([3])


def test_calibration_keeps_optional_fields_only_when_equal(calibration: dict[str, Any]) -> None:
    a = steady(calibration, 6e-9, free_amplitude_m=1e-8, tip_radius_m=8e-9)
    b = steady(calibration, 4e-9, free_amplitude_m=1e-8, tip_radius_m=9e-9)
    cal = Experiment([a, b]).calibration
    assert cal["free_amplitude_m"] == 1e-8 and "tip_radius_m" not in cal


def any_kind(calibration: dict[str, Any], kind: str) -> Trace:
    if kind == "series":
        return series_trace(calibration)
    if kind == "sweep":
        return Trace(np.zeros((2, N)), **calibration, drive_frequency_hz=[2e5, 3e5], gap_m=5e-9)
    if kind == "ramp":
        return Trace(np.zeros(N), **calibration, drive_frequency_hz=3e5,
                     gap_m=np.linspace(9e-9, 1e-9, N), segment=np.zeros(N, dtype=np.int8))
    if kind == "curves":
        return Trace(None, **calibration, drive_frequency_hz=3e5, gap_m=2e-9,
                     amplitude_m=np.ones(N), phase_rad=np.ones(N))
    return steady(calibration, 5e-9)


@pytest.mark.parametrize("kind", ["series", "sweep", "single", "ramp", "curves"])
def test_read_round_trip(tmp_path: Path, calibration: dict[str, Any], kind: str) -> None:
    trace = any_kind(calibration, kind)
    path = write_trace(trace, tmp_path / "t.h5")
    exp = Experiment.read(path)
    assert exp.kind == kind and len(exp) == trace.n_points and not exp.has_labels
    assert Experiment.from_trace(trace).kind == kind
    expected = np.atleast_1d(trace.gap_m) if kind != "ramp" else [np.nan]
    np.testing.assert_array_equal(exp.gaps_m, np.broadcast_to(expected, (len(exp),)))
    with_truth = Experiment.read(path, labels=True)
    assert with_truth.has_labels == (trace.labels is not None)


def test_read_never_touches_labels(
    tmp_path: Path, calibration: dict[str, Any], h5_names_seen: list[str]
) -> None:
    path = write_trace(series_trace(calibration), tmp_path / "t.h5")
    seen = h5_names_seen  # the spy is installed before writing; start from a clean list
    seen.clear()
    exp = Experiment.read(path)
    assert len(exp) == 3 and seen and not any("labels" in name for name in seen)
    seen.clear()
    Experiment.read(path, labels=True)
    assert any("labels" in name for name in seen)  # the spy does see label access
