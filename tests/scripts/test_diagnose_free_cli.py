"""scripts/diagnose_free.py end to end on a synthetic plain-HDF5 record (detector map known),
and one line + exit 2 on bad input."""

from __future__ import annotations

import json

import h5py
import numpy as np

from afmlearn.freeosc import simulate_free
from simulator.sensor import DetectorNonlinearity, GaussianNoise, SensorChain


def test_synthetic_record_end_to_end(tmp_path, run_script):
    sensor = SensorChain([DetectorNonlinearity(a2=-0.1), GaussianNoise(level=0.01)], seed=1)
    y, spp = simulate_free(n_periods=1500, modulation_periods=500.0, sensor=sensor)
    path = tmp_path / "record.h5"
    with h5py.File(path, "w") as f:
        f["s"] = 0.2 * y  # "nm"
        f.attrs["sample_rate_hz"] = spp * 60e3  # the file's own rate beats the config's 1.15e6
    out = tmp_path / "out"
    code, stdout, err = run_script("diagnose_free.py", f"record={path}", f"out_dir={out}",
                                   "block_periods=100")
    assert code == 0, err
    report = json.loads((out / "report.json").read_text())
    assert report["record"]["sample_rate_hz"] == spp * 60e3
    assert report["cause"] == "detector_nonlinearity"
    assert report["gain"] > 0.3
    assert (out / report["figures"][0]).stat().st_size > 10_000
    assert "detector_nonlinearity" in stdout


def test_bad_input_one_line_exit_2(tmp_path, run_script):
    missing = tmp_path / "nope.h5"
    run_script.error_line("diagnose_free.py", f"record={missing}", f"out_dir={tmp_path / 'o'}")
    short = tmp_path / "short.h5"
    with h5py.File(short, "w") as f:
        f["s"] = np.cos(np.arange(200) * 2 * np.pi / 19)
    run_script.error_line("diagnose_free.py", f"record={short}", f"out_dir={tmp_path / 'o2'}")
