"""FM spectroscopy tables (afmlearn/io/instruments/fm_table.py): the two CSV layouts, the
calibration sidecar/overrides and damaged copies (one-line RecordingError)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from afmlearn.io.instruments.errors import MissingCalibration, RecordingError
from afmlearn.io.instruments.fm_table import is_fm_table, read_fm_spectroscopy

CAL = {"spring_constant_n_per_m": 1800.0, "amplitude_m": 5e-10, "resonance_frequency_hz": 2e4}
REAL = Path(__file__).resolve().parents[4] / "shared" / "data" / "real" / "ncafm_fm_spectroscopy"


def write_map(folder: Path, df: np.ndarray, z: np.ndarray, bias: np.ndarray,
              calibration: dict | None = CAL) -> Path:
    """The nc_AFM layout: a map with an index column + z_piezo.csv (+ sidecar)."""
    folder.mkdir(parents=True, exist_ok=True)
    lines = ["," + ",".join(repr(float(v)) for v in bias)]
    lines += [f"{i}," + ",".join(repr(float(x)) for x in row) for i, row in enumerate(df)]
    (folder / "df_dataframe_test.csv").write_text("\n".join(lines) + "\n")
    (folder / "z_piezo.csv").write_text("\n".join(repr(float(x)) for x in z) + "\n")
    if calibration is not None:
        (folder / "fm_calibration.json").write_text(json.dumps(calibration))
    return folder


@pytest.fixture
def small(tmp_path):
    rng = np.random.default_rng(0)
    z = -30e-9 + 0.2e-9 * np.arange(6)
    bias = np.array([2.0, 1.0, 0.0, -1.0])
    df = rng.normal(size=(6, 4))
    return write_map(tmp_path / "map", df, z, bias), df, z, bias


def test_map_folder_reads_in_si_with_the_sidecar_calibration(small):
    folder, df, z, bias = small
    assert is_fm_table(folder)
    spec = read_fm_spectroscopy(folder)
    np.testing.assert_array_equal(spec.frequency_shift_hz, df)
    np.testing.assert_array_equal(spec.z_piezo_m, z)
    np.testing.assert_array_equal(spec.bias_v, bias)
    assert spec.spring_constant_n_per_m == 1800.0 and spec.amplitude_m == 5e-10
    # overrides win over the sidecar
    assert read_fm_spectroscopy(folder, amplitude_m=1e-9).amplitude_m == 1e-9


def test_a_european_export_reads_like_the_comma_map(small, tmp_path):
    """``;``-separated with decimal commas and a byte-order mark (spreadsheet export), the
    same numbers as the comma map."""
    folder, df, z, bias = small
    eu = tmp_path / "eu"
    eu.mkdir()
    for name in ("df_dataframe_test.csv", "z_piezo.csv", "fm_calibration.json"):
        text = (folder / name).read_text()
        if name.endswith(".csv"):
            text = "\ufeff" + text.replace(",", ";").replace(".", ",")
        (eu / name).write_text(text, encoding="utf-8")
    assert is_fm_table(eu / "df_dataframe_test.csv")
    spec = read_fm_spectroscopy(eu)
    np.testing.assert_array_equal(spec.frequency_shift_hz, df)
    np.testing.assert_array_equal(spec.z_piezo_m, z)
    np.testing.assert_array_equal(spec.bias_v, bias)


def test_column_table_with_z_in_the_first_column(tmp_path):
    path = tmp_path / "all.csv"
    path.write_text("z,-0.0,1.75,4.0\n-3e-08,1,2,3\n-2.98e-08,4,5,6\n-2.96e-08,7,8,9\n")
    spec = read_fm_spectroscopy(path, **CAL)
    assert spec.shape == (3, 3)
    np.testing.assert_allclose(spec.z_piezo_m, [-3e-8, -2.98e-8, -2.96e-8])
    np.testing.assert_allclose(spec.frequency_shift_hz[:, 1], [2, 5, 8])


def test_missing_calibration_names_the_field(small):
    folder, *_ = small
    (folder / "fm_calibration.json").unlink()
    with pytest.raises(MissingCalibration, match="spring_constant_n_per_m") as err:
        read_fm_spectroscopy(folder)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("damage", ["truncated", "non_numeric", "shape", "few_rows", "range"])
def test_damaged_copies_raise_one_line(small, damage):
    folder, *_ = small
    table = folder / "df_dataframe_test.csv"
    lines = table.read_text().splitlines()
    kw = {}
    if damage == "truncated":
        table.write_text("\n".join(lines[:-1] + [lines[-1][: len(lines[-1]) // 2]]) + "\n")
    elif damage == "non_numeric":
        cells = lines[3].split(",")
        cells[2] = "abc"
        table.write_text("\n".join([*lines[:3], ",".join(cells), *lines[4:]]) + "\n")
    elif damage == "shape":
        zf = folder / "z_piezo.csv"
        zf.write_text("\n".join(zf.read_text().splitlines()[:-1]) + "\n")
    elif damage == "few_rows":
        table.write_text("\n".join(lines[:3]) + "\n")
    else:
        kw = {"amplitude_m": 1.0}
    with pytest.raises(RecordingError) as err:
        read_fm_spectroscopy(folder, **kw)
    assert "\n" not in str(err.value)


@pytest.mark.skipif(not REAL.is_dir(), reason=f"nc_AFM example data (GPL-3.0) not at {REAL}")
def test_real_map_and_six_bias_table_agree():
    spec = read_fm_spectroscopy(REAL, **CAL)
    assert spec.shape == (113, 801)
    assert spec.bias_v[0] == 10.0 and spec.bias_v[-1] == -10.0
    assert np.all(np.diff(spec.z_piezo_m) > 0)
    six = read_fm_spectroscopy(REAL / "all_data_dataframe_237K.csv", **CAL)
    assert six.shape == (113, 6)
    np.testing.assert_allclose(six.z_piezo_m, spec.z_piezo_m, rtol=1e-6)
    j = int(np.argmin(np.abs(spec.bias_v - 10.0)))
    np.testing.assert_allclose(six.frequency_shift_hz[:, -1], spec.frequency_shift_hz[:, j],
                               rtol=1e-5)
    # repulsive (Δf > 0) at the closest position: z larger = further from the sample
    assert spec.frequency_shift_hz[0, j] > 10 > spec.frequency_shift_hz[-1, j]


def test_registry_sends_an_fm_table_to_the_fm_analysis(small):
    from afmlearn.io.instruments import reader_for

    folder, *_ = small
    with pytest.raises(RecordingError, match="analyze_fm.py"):
        reader_for(folder / "df_dataframe_test.csv")
