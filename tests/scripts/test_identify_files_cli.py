"""scripts/identify.py with a list of files (one tip, two free amplitudes): one experiment."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from afmlearn.identify.infer import read_files
from afmlearn.io import read_trace
from afmlearn.simulate import simulate

ROOT = Path(__file__).resolve().parents[2]
#: two short set-point series of one lever at free amplitudes 1.5 and 3 rest-gap units
SERIES = ["scenario=spectroscopy", "scenario.gap_ratios=[0.8,0.6,0.4]",
          "scenario.n_periods=30", "scenario.samples_per_period=100",
          "cantilever.quality_factor=120", "noise.level=0.002", "free_trace_periods=5",
          "progress=false"]


@pytest.fixture(scope="module")
def two_files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("files")
    paths = []
    for name, extra in (("a15.h5", []), ("a30.h5", ["excitation.free_amplitude_ratio=3.0"])):
        with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
            cfg = compose("simulate", overrides=[*SERIES, *extra, f"output={folder / name}"])
        simulate(cfg)
        paths.append(folder / name)
    return paths[0], paths[1]


def test_read_files_keeps_every_row_and_its_origin(two_files):
    exp, origin = read_files(two_files)
    assert len(exp) == 6 and origin == [(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (1, 2)]
    low, high = (read_trace(p) for p in two_files)
    np.testing.assert_array_equal(exp.gaps_m, [*np.ravel(low.gap_m), *np.ravel(high.gap_m)])
    assert not exp.has_labels                       # /labels never read


def test_two_files_are_identified_jointly(tmp_path, two_files, run_script):
    """Both files' rows in one fit: each row driven by its own calibrated drive (1 : 2), the
    force aligned row by row with the inputs, and a repulsive peak of the simulated size."""
    out = tmp_path / "out"
    code, stdout, err = run_script(
        "identify.py", f"trace=[{two_files[0]},{two_files[1]}]", f"out_dir={out}",
        "identifier=fast", "figures=false", "+identifier.output_error=null")  # EE stages only
    assert code == 0, err
    assert "interaction exponent" in stdout
    res = json.loads((out / "result.json").read_text())
    joint = res["joint"]
    assert joint["n_observations"] == 6
    assert joint["inputs"] == [str(p.resolve()) for p in two_files]
    ratios = np.asarray(joint["drive_ratios"])
    np.testing.assert_allclose(ratios[3:] / ratios[:3], 2.0, rtol=5e-3)
    truth = [read_trace(p, labels=True) for p in two_files]
    true_peak = max(float(np.max(t.labels.force_n)) for t in truth)
    with h5py.File(out / "force.h5", "r") as f:
        force = f["force_n"][()]
        origin = f["origin"][()]
        assert list(f.attrs["inputs"]) == joint["inputs"]
    assert force.shape == (6, truth[0].n_samples)
    np.testing.assert_array_equal(origin[:, 0], [0, 0, 0, 1, 1, 1])
    # the deepest-indentation row's peak: the identified law within 15 % of the simulated one
    assert np.nanmax(force) == pytest.approx(true_peak, rel=0.15)


def test_single_path_list_is_the_single_path(tmp_path, two_files, run_script):
    """``trace=[a.h5]`` is ``trace=a.h5``: bad input gives the same one-line error."""
    bad = tmp_path / "short.h5"
    shutil.copy(two_files[0], bad)
    with h5py.File(bad, "r+") as f:
        f.attrs["sample_rate_hz"] = 15.0 * f.attrs["drive_frequency_hz"]
    one = run_script.error_line("identify.py", f"trace={bad}", f"out_dir={tmp_path / 'o'}")
    listed = run_script.error_line("identify.py", f"trace=[{bad}]", f"out_dir={tmp_path / 'o'}")
    assert one == listed and "samples per" in one


def test_files_of_another_cantilever_exit_2_with_one_line(tmp_path, two_files, run_script):
    other = tmp_path / "other_lever.h5"
    shutil.copy(two_files[1], other)
    with h5py.File(other, "r+") as f:
        f.attrs["spring_constant_n_per_m"] = 2.0 * f.attrs["spring_constant_n_per_m"]
    out = tmp_path / "out"
    line = run_script.error_line("identify.py", f"trace=[{two_files[0]},{other}]",
                                 f"out_dir={out}")
    assert "a15.h5" in line and "other_lever.h5" in line and "spring_constant" in line, line
    assert not (out / "result.json").exists()


def test_row_with_several_files_is_refused(tmp_path, two_files, run_script):
    line = run_script.error_line("identify.py", f"trace=[{two_files[0]},{two_files[1]}]",
                                 "row=1", f"out_dir={tmp_path / 'o'}")
    assert "row must be null" in line
