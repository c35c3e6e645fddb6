"""Optional fields of design.md section 2: set-point series, drive phase, segment, lock-in."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from afmlearn.io import (
    Labels,
    Trace,
    TraceFormatError,
    TraceReader,
    TraceWriter,
    read_trace,
    write_trace,
)

N, N_POINTS = 64, 4


@pytest.fixture
def series(calibration: dict[str, Any]) -> Trace:
    """A set-point series: 2-D deflection, one rest gap and one drive phase per row."""
    rng = np.random.default_rng(2)
    shape = (N_POINTS, N)
    return Trace(
        1e-8 * rng.standard_normal(shape),
        **calibration,
        drive_frequency_hz=2.99e5,
        gap_m=np.linspace(9e-9, 4e-9, N_POINTS),
        drive_phase_rad=np.linspace(0.1, 2.0, N_POINTS),
        free_amplitude_m=10e-9,
        labels=Labels(
            1e-9 * rng.standard_normal(shape),
            modal_m=1e-8 * rng.standard_normal((1, *shape)),
            model={"name": "vdw_dmt"},
            scalars={"dissipated_energy_j": np.linspace(1e-19, 4e-19, N_POINTS), "q": 1.0},
        ),
    )


@pytest.fixture
def ramp(calibration: dict[str, Any]) -> Trace:
    """An approach-retract ramp with its segment and drive phase."""
    half = N // 2
    gap = np.concatenate([np.linspace(20e-9, 5e-9, half), np.linspace(5e-9, 20e-9, half)])
    segment = np.repeat(np.array([0, 1], dtype=np.int8), half)
    return Trace(
        np.sin(np.arange(N)) * 1e-8,
        **calibration,
        drive_frequency_hz=3e5,
        gap_m=gap,
        segment=segment,
        drive_phase_rad=-0.7,
    )


@pytest.fixture
def curves(calibration: dict[str, Any]) -> Trace:
    """Lock-in curves without a deflection record."""
    z = np.linspace(30e-9, 2e-9, N)
    return Trace(
        None,
        **calibration,
        drive_frequency_hz=3e5,
        gap_m=z,
        amplitude_m=np.minimum(10e-9, z),
        phase_rad=np.full(N, np.pi / 2),
        z_piezo_m=z,
        segment=np.zeros(N, dtype=np.int8),
        lockin_bandwidth_hz=1e3,
    )


@pytest.fixture
def bimodal(curves: Trace) -> Trace:
    """Bimodal lock-in curves: a second amplitude and phase at the second drive frequency."""
    z = curves.z_piezo_m
    assert z is not None
    return Trace(None, **{**curves.metadata(), "amplitude2_m": 1e-9 * (1 + z / z.max()),
                          "phase2_rad": np.linspace(1.5, 1.7, N), "drive_frequency2_hz": 1.9e6})


def test_series_properties_and_rows(series: Trace) -> None:
    assert series.is_series and series.has_rows and not series.is_sweep
    assert series.n_points == N_POINTS
    for i in range(N_POINTS):
        row = series.row(i)
        assert not row.has_rows and not row.is_series
        np.testing.assert_array_equal(row.deflection_m, series.deflection_m[i])
        assert row.gap_m == series.gap_m[i]  # type: ignore[index]
        assert row.drive_phase_rad == series.drive_phase_rad[i]  # type: ignore[index]
        assert row.drive_frequency_hz == series.drive_frequency_hz
        assert row.labels is not None and series.labels is not None
        np.testing.assert_array_equal(row.labels.force_n, series.labels.force_n[i])
        np.testing.assert_array_equal(row.labels.modal_m, series.labels.modal_m[:, i])
        assert row.labels.scalars["dissipated_energy_j"] == pytest.approx(
            series.labels.scalars["dissipated_energy_j"][i]  # type: ignore[index]
        )
        assert row.labels.scalars["q"] == 1.0
    with pytest.raises(ValueError, match=r"i must be in \[0, 4\)"):
        series.row(N_POINTS)


def test_single_row_is_itself(ramp: Trace) -> None:
    assert ramp.row(0) is ramp and ramp.is_ramp
    with pytest.raises(ValueError, match="i must be"):
        ramp.row(1)


def test_sweep_row_keeps_a_scalar_phase(calibration: dict[str, Any]) -> None:
    sweep = Trace(
        np.zeros((3, 8)), **calibration, drive_frequency_hz=[1e5, 2e5, 3e5], gap_m=1e-8,
        drive_phase_rad=0.5,
    )
    assert sweep.is_sweep and not sweep.is_series
    assert sweep.row(2).drive_frequency_hz == 3e5 and sweep.row(2).drive_phase_rad == 0.5


@pytest.mark.parametrize("fixture", ["series", "ramp", "curves", "bimodal"])
def test_round_trip(
    tmp_path: Path, fixture: str, request: pytest.FixtureRequest, assert_same: Any
) -> None:
    trace: Trace = request.getfixturevalue(fixture)
    back = read_trace(write_trace(trace, tmp_path / "t.h5"), labels=True)
    if trace.deflection_m is None:
        assert back.deflection_m is None
        back = Trace(np.zeros(N), **back.metadata())  # compare metadata with a stand-in
        trace = Trace(np.zeros(N), **trace.metadata())
    assert_same(trace, back, labels=trace.labels is not None)
    if trace.segment is not None:
        assert back.segment is not None and back.segment.dtype == np.int8
    for name in ("amplitude2_m", "phase2_rad", "drive_frequency2_hz"):
        np.testing.assert_array_equal(getattr(back, name), getattr(trace, name))


def test_layout_of_the_new_fields(tmp_path: Path, series: Trace, ramp: Trace) -> None:
    write_trace(series, tmp_path / "s.h5")
    write_trace(ramp, tmp_path / "r.h5")
    with h5py.File(tmp_path / "s.h5") as f:
        assert f["gap_m"].shape == (N_POINTS,) and f["drive_phase_rad"].shape == (N_POINTS,)
        assert f.attrs["drive_frequency_hz"] == pytest.approx(2.99e5)
    with h5py.File(tmp_path / "r.h5") as f:
        assert f.attrs["drive_phase_rad"] == pytest.approx(-0.7)
        assert f["segment"].dtype == np.int8


def test_reader_rows_of_a_series(tmp_path: Path, series: Trace) -> None:
    path = write_trace(series, tmp_path / "s.h5")
    with TraceReader(path, labels=True) as reader:
        assert reader.is_series and not reader.is_sweep and len(reader) == N_POINTS
        for i, row in enumerate(reader):
            expected = series.row(i)
            assert row.gap_m == expected.gap_m
            assert row.drive_phase_rad == expected.drive_phase_rad
            np.testing.assert_array_equal(row.deflection_m, expected.deflection_m)
            assert row.labels is not None
            assert row.labels.scalars["dissipated_energy_j"] == pytest.approx(
                expected.labels.scalars["dissipated_energy_j"]  # type: ignore[union-attr]
            )


def test_streaming_writer_takes_the_phase_per_row(tmp_path: Path, series: Trace) -> None:
    meta = {k: v for k, v in series.metadata().items() if k != "drive_phase_rad"}
    path = tmp_path / "s.h5"
    with TraceWriter(path, n_samples=N, n_points=N_POINTS, **meta) as writer:
        for i in reversed(range(N_POINTS)):
            writer.write_row(i, series.deflection_m[i],  # type: ignore[index]
                             drive_phase_rad=series.drive_phase_rad[i])  # type: ignore[index]
    np.testing.assert_array_equal(read_trace(path).drive_phase_rad, series.drive_phase_rad)
    with pytest.raises(ValueError, match="every row or for none"):
        with TraceWriter(tmp_path / "x.h5", n_samples=N, n_points=N_POINTS, **meta) as writer:
            writer.write_row(0, np.zeros(N), drive_phase_rad=0.0)
            writer.write_row(1, np.zeros(N))
    with pytest.raises(ValueError, match="already given"):
        with TraceWriter(tmp_path / "x.h5", n_samples=N, n_points=N_POINTS,
                         **series.metadata()) as writer:
            writer.write_row(0, np.zeros(N), drive_phase_rad=0.0)
    assert not (tmp_path / "x.h5").exists()


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"drive_phase_rad": np.zeros(3)}, "drive_phase_rad must be a number or an array of "
                                           r"shape \(n_points,\) = \(4,\)"),
        ({"drive_phase_rad": np.nan}, "drive_phase_rad must be a finite number"),
        ({"gap_m": np.zeros(3)}, r"gap_m must be a number or an array of shape \(n_points,\)"),
        ({"gap_m": 1e-8}, r"drive_frequency_hz must be an array of shape \(n_points,\)"),
        ({"segment": np.zeros(N)}, "segment is allowed only with a 1-D deflection_m"),
        ({"amplitude_m": np.zeros(N)}, "amplitude_m is allowed only with a 1-D"),
    ],
)
def test_series_validation(series: Trace, changes: dict[str, Any], match: str) -> None:
    kwargs = {**series.metadata(), **changes}
    with pytest.raises(ValueError, match=match):
        Trace(series.deflection_m, **kwargs)


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"segment": np.zeros(N - 1, dtype=np.int8)}, r"segment must have shape \(n,\) = \(64,\)"),
        ({"segment": np.full(N, 2)}, "segment must hold only 0 .* and 1"),
        ({"segment": np.full(N, 0.5)}, "segment must hold integers"),
        ({"drive_phase_rad": np.zeros(N)}, "drive_phase_rad must be a single number"),
        ({"amplitude_m": np.zeros(N - 1)}, r"amplitude_m must have shape \(64,\)"),
        ({"amplitude_m": -np.ones(N)}, "amplitude_m must be >= 0"),
        ({"phase_rad": np.zeros(N)}, "phase_rad needs amplitude_m"),
        ({"amplitude_m": np.ones(N), "z_piezo_m": np.ones(3)}, "z_piezo_m must have shape"),
        ({"lockin_bandwidth_hz": 0.0}, "lockin_bandwidth_hz must be a finite number > 0"),
        ({"amplitude2_m": np.ones(N)}, "amplitude2_m needs amplitude_m"),
        ({"amplitude_m": np.ones(N), "phase2_rad": np.ones(N)}, "phase2_rad needs amplitude2_m"),
        ({"amplitude_m": np.ones(N), "amplitude2_m": -np.ones(N)}, "amplitude2_m must be >= 0"),
        ({"amplitude_m": np.ones(N), "amplitude2_m": np.ones(3)}, "amplitude2_m must have shape"),
        ({"amplitude_m": np.ones(N), "drive_frequency2_hz": 2e6},
         "drive_frequency2_hz needs amplitude2_m"),
    ],
)
def test_ramp_and_curve_validation(ramp: Trace, changes: dict[str, Any], match: str) -> None:
    kwargs = {**ramp.metadata(), **changes}
    with pytest.raises(ValueError, match=match):
        Trace(ramp.deflection_m, **kwargs)


def test_deflection_may_be_absent_only_for_curves(ramp: Trace, curves: Trace) -> None:
    with pytest.raises(ValueError, match="deflection_m may be None only for lock-in curves"):
        Trace(None, **ramp.metadata())
    with pytest.raises(ValueError, match="labels need deflection_m"):
        Trace(None, **curves.metadata(), labels=Labels(np.zeros(N)))


def _old_file(path: Path, *, rows: bool) -> Path:
    """A version-1 file as written before the optional fields existed (raw h5py)."""
    with h5py.File(path, "w") as f:
        f.attrs.update({"format": "afmlearn-trace", "format_version": 1, "sample_rate_hz": 1e6,
                        "spring_constant_n_per_m": 2.0, "quality_factor": 200.0,
                        "resonance_frequency_hz": 7e4, "gap_m": 1e-8})
        if rows:
            f["deflection_m"] = np.zeros((3, 16))
            f["drive_frequency_hz"] = np.linspace(6e4, 8e4, 3)
        else:
            f["deflection_m"] = np.zeros(16)
            f.attrs["drive_frequency_hz"] = 7e4
    return path


@pytest.mark.parametrize("rows", [False, True])
def test_old_version_1_files_still_read(tmp_path: Path, rows: bool) -> None:
    trace = read_trace(_old_file(tmp_path / "old.h5", rows=rows))
    assert trace.is_sweep == rows and not trace.is_series
    for name in ("drive_phase_rad", "segment", "amplitude_m", "phase_rad", "z_piezo_m",
                 "lockin_bandwidth_hz"):
        assert getattr(trace, name) is None, name


def test_malformed_new_fields_in_files(tmp_path: Path) -> None:
    path = _old_file(tmp_path / "bad.h5", rows=True)
    with h5py.File(path, "r+") as f:
        f["drive_phase_rad"] = np.zeros(2)
    with pytest.raises(TraceFormatError, match="bad.h5: drive_phase_rad must be"):
        read_trace(path)
    path = _old_file(tmp_path / "bad2.h5", rows=False)
    with h5py.File(path, "r+") as f:
        f["segment"] = np.full(16, 3, dtype=np.int8)
    with pytest.raises(TraceFormatError, match="bad2.h5: segment must hold only"):
        read_trace(path)
    with h5py.File(path, "r+") as f:
        del f["segment"], f["deflection_m"]
    with pytest.raises(TraceFormatError, match="missing required dataset 'deflection_m'"):
        read_trace(path)
