"""`TraceWriter` (row by row, block by block) and `TraceReader` / `read_rows`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from afmlearn.io import Trace, TraceReader, TraceWriter, read_rows, read_trace, write_trace


def sweep_writer(path: Path, sweep: Trace, **kwargs: Any) -> TraceWriter:
    return TraceWriter(
        path,
        n_points=sweep.n_points,
        n_samples=sweep.n_samples,
        **kwargs,
        **sweep.metadata(),
    )


def test_sweep_rows_in_any_order(tmp_path: Path, sweep: Trace) -> None:
    labels = sweep.labels
    assert labels is not None and labels.modal_m is not None
    path = tmp_path / "s.h5"
    energy = np.arange(sweep.n_points) * 1e-19
    with sweep_writer(path, sweep, n_modes=2, model={"name": "vdw_dmt"}) as writer:
        assert not path.exists()
        for i in reversed(range(sweep.n_points)):
            writer.write_row(
                i,
                sweep.deflection_m[i],
                force_n=labels.force_n[i],
                modal_m=labels.modal_m[:, i],
                scalars={"dissipated_energy_j": energy[i]},
            )
    back = read_trace(path, labels=True)
    np.testing.assert_array_equal(back.deflection_m, sweep.deflection_m)
    np.testing.assert_array_equal(back.drive_frequency_hz, sweep.drive_frequency_hz)
    assert back.labels is not None
    np.testing.assert_array_equal(back.labels.modal_m, labels.modal_m)
    np.testing.assert_array_equal(back.labels.scalars["dissipated_energy_j"], energy)
    with h5py.File(path) as f:
        assert f["deflection_m"].chunks == (1, sweep.n_samples)
        assert f["labels/force_n"].chunks == (1, sweep.n_samples)


def test_single_trace_in_blocks(tmp_path: Path, single: Trace, assert_same: Any) -> None:
    labels = single.labels
    assert labels is not None and labels.modal_m is not None
    path = tmp_path / "t.h5"
    with TraceWriter(
        path,
        n_samples=single.n_samples,
        n_modes=2,
        model=labels.model,
        effect=labels.effect,
        scalars=labels.scalars,
        extra=labels.extra,
        **single.metadata(),
    ) as writer:
        for start in range(0, single.n_samples, 100):
            block = slice(start, start + 100)
            writer.append(
                single.deflection_m[block],
                force_n=labels.force_n[block],
                modal_m=labels.modal_m[:, block],
            )
    assert_same(single, read_trace(path, labels=True), labels=True)


def test_exception_inside_with_leaves_nothing(tmp_path: Path, sweep: Trace) -> None:
    with pytest.raises(RuntimeError, match="simulation diverged"):
        with sweep_writer(tmp_path / "s.h5", sweep) as writer:
            writer.write_row(0, sweep.deflection_m[0])
            raise RuntimeError("simulation diverged")
    assert list(tmp_path.iterdir()) == []


def test_missing_rows_leave_nothing(tmp_path: Path, sweep: Trace) -> None:
    with pytest.raises(ValueError, match=r"rows were never written \(1, 2, 3, 4\)"):
        with sweep_writer(tmp_path / "s.h5", sweep) as writer:
            writer.write_row(0, sweep.deflection_m[0])
    assert list(tmp_path.iterdir()) == []


def test_short_single_trace_leaves_nothing(tmp_path: Path, single: Trace) -> None:
    with pytest.raises(ValueError, match="n_samples"):
        with TraceWriter(tmp_path / "t.h5", n_samples=single.n_samples, **single.metadata()) as w:
            w.append(single.deflection_m[:10])
    assert list(tmp_path.iterdir()) == []


def test_existing_file_survives_a_failed_rewrite(
    tmp_path: Path, sweep: Trace, single: Trace
) -> None:
    path = write_trace(single, tmp_path / "s.h5")
    with pytest.raises(ValueError):
        with sweep_writer(path, sweep):
            pass
    assert not read_trace(path).is_sweep
    assert [p.name for p in tmp_path.iterdir()] == ["s.h5"]


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda w, row: w.write_row(5, row), r"i must be in \[0, 5\)"),
        (lambda w, row: w.write_row(0, row[:-1]), "deflection_m"),
        (lambda w, row: w.write_row(0, np.full_like(row, np.nan)), "deflection_m must be finite"),
        (lambda w, row: w.write_row(0, row, force_n=row), "force_n given"),
        (lambda w, row: w.write_row(0, row, scalars={"e_j": 1.0}), "scalars given"),
        (lambda w, row: w.append(row), "append needs a single trace"),
    ],
)
def test_bad_rows_are_rejected(tmp_path: Path, sweep: Trace, call: Any, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        with sweep_writer(tmp_path / "s.h5", sweep) as writer:
            call(writer, sweep.deflection_m[0])
    assert list(tmp_path.iterdir()) == []


def test_row_scalars_must_be_consistent(tmp_path: Path, sweep: Trace) -> None:
    row, force = sweep.deflection_m[0], np.zeros(sweep.n_samples)
    with pytest.raises(ValueError, match="same quantities in every row"):
        with sweep_writer(tmp_path / "s.h5", sweep, model={}) as writer:
            writer.write_row(0, row, force_n=force, scalars={"a": 1.0})
            writer.write_row(1, row, force_n=force, scalars={"b": 1.0})


def test_writer_checks_its_arguments(tmp_path: Path, sweep: Trace) -> None:
    with pytest.raises(ValueError, match="n_points must be an integer >= 1"):
        TraceWriter(tmp_path / "s.h5", n_points=0, n_samples=10, **sweep.metadata())
    with pytest.raises(ValueError, match="does not exist"):
        TraceWriter(tmp_path / "no" / "s.h5", n_points=5, n_samples=10, **sweep.metadata())
    with pytest.raises(ValueError, match="drive_frequency_hz"):
        TraceWriter(tmp_path / "s.h5", n_points=3, n_samples=10, **sweep.metadata())
    with pytest.raises(ValueError, match="model is required"):
        TraceWriter(tmp_path / "s.h5", n_points=5, n_samples=10, n_modes=1, **sweep.metadata())
    with pytest.raises(TypeError, match="quality_factor"):
        metadata = {k: v for k, v in sweep.metadata().items() if k != "quality_factor"}
        TraceWriter(tmp_path / "s.h5", n_points=5, n_samples=10, **metadata)
    writer = sweep_writer(tmp_path / "s.h5", sweep)
    with pytest.raises(RuntimeError, match="with"):
        writer.write_row(0, sweep.deflection_m[0])
    assert list(tmp_path.iterdir()) == []


def test_reader_streams_rows(tmp_path: Path, sweep: Trace) -> None:
    path = write_trace(sweep, tmp_path / "s.h5")
    with TraceReader(path, labels=True) as reader:
        assert len(reader) == sweep.n_points and reader.shape == sweep.deflection_m.shape
        row = reader.row(2)
        with pytest.raises(ValueError, match="i must be in"):
            reader.row(sweep.n_points)
    assert sweep.labels is not None and sweep.labels.modal_m is not None
    np.testing.assert_array_equal(row.deflection_m, sweep.deflection_m[2])
    assert row.drive_frequency_hz == sweep.drive_frequency_hz[2]
    assert row.labels is not None and row.labels.modal_m is not None
    np.testing.assert_array_equal(row.labels.force_n, sweep.labels.force_n[2])
    np.testing.assert_array_equal(row.labels.modal_m, sweep.labels.modal_m[:, 2])
    assert row.labels.scalars["contact_fraction"] == pytest.approx(0.2)
    assert row.labels.scalars["coupling_strength"] == pytest.approx(0.3)
    rows = list(read_rows(path))
    assert len(rows) == sweep.n_points and all(r.labels is None for r in rows)
    np.testing.assert_array_equal(np.stack([r.deflection_m for r in rows]), sweep.deflection_m)


def test_reader_reads_one_row_at_a_time(
    tmp_path: Path, sweep: Trace, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = write_trace(sweep, tmp_path / "s.h5")
    shapes: list[tuple[int, ...]] = []
    original = h5py.Dataset.__getitem__

    def spy(self: h5py.Dataset, key: Any, *args: Any) -> Any:
        out = original(self, key, *args)
        if self.name == "/deflection_m":
            shapes.append(np.shape(out))
        return out

    monkeypatch.setattr(h5py.Dataset, "__getitem__", spy)
    assert sum(1 for _ in read_rows(path)) == sweep.n_points
    assert shapes == [(sweep.n_samples,)] * sweep.n_points


def test_single_file_reads_as_one_row(tmp_path: Path, single: Trace, assert_same: Any) -> None:
    path = write_trace(single, tmp_path / "t.h5")
    rows = list(read_rows(path, labels=True))
    assert len(rows) == 1
    assert_same(single, rows[0], labels=True)
