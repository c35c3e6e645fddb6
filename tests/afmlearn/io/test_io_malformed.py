"""Malformed files (built with raw h5py) are rejected with a `TraceFormatError` naming the fault."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest

from afmlearn.io import TraceFormatError, read_rows, read_trace

N, N_POINTS = 32, 3
Mutation = Callable[[h5py.File], None]


def build(path: Path, mutate: Mutation, *, sweep: bool = False) -> Path:
    """A valid file written with raw h5py, then changed by ``mutate``."""
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "afmlearn-trace"
        f.attrs["format_version"] = 1
        f.attrs["sample_rate_hz"] = 1e6
        f.attrs["spring_constant_n_per_m"] = 2.0
        f.attrs["quality_factor"] = 200.0
        f.attrs["resonance_frequency_hz"] = 7e4
        f.attrs["gap_m"] = 1e-8
        if sweep:
            f["deflection_m"] = np.zeros((N_POINTS, N))
            f["drive_frequency_hz"] = np.linspace(6e4, 8e4, N_POINTS)
        else:
            f["deflection_m"] = np.zeros(N)
            f.attrs["drive_frequency_hz"] = 7e4
        labels = f.create_group("labels")
        labels["force_n"] = np.zeros(f["deflection_m"].shape)
        labels.attrs["model"] = '{"name": "vdw_dmt"}'
        labels.attrs["effect"] = "none"
        mutate(f)
    return path


def replace(name: str, value: object) -> Mutation:
    def mutate(f: h5py.File) -> None:
        del f[name]
        f[name] = value

    return mutate


def set_attr(name: str, value: object, where: str = "/") -> Mutation:
    def mutate(f: h5py.File) -> None:
        f[where].attrs[name] = value

    return mutate


def as_dataset(name: str, value: object) -> Mutation:
    """Replace attribute ``name`` by a dataset."""

    def mutate(f: h5py.File) -> None:
        del f.attrs[name]
        f[name] = value

    return mutate


def as_attr(name: str, value: object) -> Mutation:
    """Replace dataset ``name`` by an attribute."""

    def mutate(f: h5py.File) -> None:
        del f[name]
        f.attrs[name] = value

    return mutate


def del_attr(name: str) -> Mutation:
    def mutate(f: h5py.File) -> None:
        del f.attrs[name]

    return mutate


def test_the_builder_makes_valid_files(tmp_path: Path) -> None:
    assert read_trace(build(tmp_path / "a.h5", lambda f: None), labels=True).labels is not None
    assert read_trace(build(tmp_path / "b.h5", lambda f: None, sweep=True)).n_points == N_POINTS


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(TraceFormatError, match="nope.h5: no such file"):
        read_trace(tmp_path / "nope.h5")


def test_not_hdf5(tmp_path: Path) -> None:
    path = tmp_path / "text.h5"
    path.write_text("time,deflection\n0,1\n")
    with pytest.raises(TraceFormatError, match="text.h5: not a readable HDF5 file"):
        read_trace(path)


CASES: dict[str, tuple[Mutation, str]] = {
    "wrong format": (set_attr("format", "csv-trace"), "'format' must be 'afmlearn-trace'"),
    "no format": (del_attr("format"), "'format' .* it is missing"),
    "version 2": (set_attr("format_version", 2), "'format_version' .* found 2"),
    "float version": (set_attr("format_version", 1.0), "'format_version'"),
    "no sample rate": (del_attr("sample_rate_hz"), "missing required attribute 'sample_rate_hz'"),
    "no spring constant": (del_attr("spring_constant_n_per_m"), "'spring_constant_n_per_m'"),
    "no Q": (del_attr("quality_factor"), "missing required attribute 'quality_factor'"),
    "no f0": (del_attr("resonance_frequency_hz"), "'resonance_frequency_hz'"),
    "no drive": (del_attr("drive_frequency_hz"), "attribute or dataset 'drive_frequency_hz'"),
    "no gap": (del_attr("gap_m"), "missing required attribute or dataset 'gap_m'"),
    "no deflection": (lambda f: f.__delitem__("deflection_m"), "dataset 'deflection_m'"),
    "3-D deflection": (replace("deflection_m", np.zeros((2, 3, N))), "shape \\(2, 3, 32\\)"),
    "text deflection": (replace("deflection_m", np.array([b"a", b"b"])), "'deflection_m'"),
    "NaN deflection": (
        replace("deflection_m", np.r_[np.zeros(N - 1), np.nan]),
        "deflection_m must be finite, found 1 NaN",
    ),
    "NaN Q": (set_attr("quality_factor", np.nan), "quality_factor must be a finite number > 0"),
    "inf f0": (set_attr("resonance_frequency_hz", np.inf), "resonance_frequency_hz"),
    "zero k": (set_attr("spring_constant_n_per_m", 0.0), "spring_constant_n_per_m .*got 0.0"),
    "negative rate": (set_attr("sample_rate_hz", -1e6), "sample_rate_hz"),
    "text rate": (set_attr("sample_rate_hz", "1 MHz"), "sample_rate_hz must be a real number"),
    "negative drive": (set_attr("drive_frequency_hz", -7e4), "drive_frequency_hz"),
    "NaN gap": (set_attr("gap_m", np.nan), "gap_m must be a finite number"),
    "short gap dataset": (
        as_dataset("gap_m", np.ones(N - 1)),
        "gap_m must be a number or an array of shape \\(n,\\) = \\(32,\\), got shape \\(31,\\)",
    ),
    "inf in gap dataset": (
        as_dataset("gap_m", np.full(N, np.inf)),
        "gap_m must be finite, found 32 NaN/inf",
    ),
    "gap attr and dataset": (lambda f: f.create_dataset("gap_m", data=np.ones(N)), "both"),
    "drive dataset on 1-D": (
        as_dataset("drive_frequency_hz", np.ones(N_POINTS)),
        "drive_frequency_hz must be a single number",
    ),
    "bad excitation": (set_attr("excitation", "side"), "excitation must be one of"),
    "bad dither": (set_attr("dither_amplitude_m", -1e-9), "dither_amplitude_m"),
    "NaN free deflection": (
        lambda f: f.create_dataset("free_deflection_m", data=[0.0, np.nan]),
        "free_deflection_m must be finite",
    ),
}


@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_malformed_single(tmp_path: Path, case: str) -> None:
    mutate, match = CASES[case]
    path = build(tmp_path / "bad.h5", mutate)
    with pytest.raises(TraceFormatError, match=match) as info:
        read_trace(path)
    assert "bad.h5" in str(info.value)
    with pytest.raises(TraceFormatError, match=match):
        list(read_rows(path))  # header faults on opening, data faults on reading the row


SWEEP_CASES: dict[str, tuple[Mutation, str]] = {
    "short drive dataset": (
        replace("drive_frequency_hz", np.ones(N_POINTS - 1)),
        "drive_frequency_hz must be an array of shape \\(n_points,\\) = \\(3,\\) .*\\(2,\\)",
    ),
    "drive as attribute": (
        as_attr("drive_frequency_hz", 1.0),
        "drive_frequency_hz must be an array .*got shape \\(\\)",
    ),
    "zero drive in dataset": (
        replace("drive_frequency_hz", np.array([1.0, 0.0, 1.0])),
        "drive_frequency_hz .* > 0",
    ),
    "NaN row": (
        replace("deflection_m", np.vstack([np.zeros((2, N)), np.full((1, N), np.nan)])),
        "deflection_m must be finite",
    ),
}


@pytest.mark.parametrize("case", SWEEP_CASES, ids=list(SWEEP_CASES))
def test_malformed_sweep(tmp_path: Path, case: str) -> None:
    mutate, match = SWEEP_CASES[case]
    path = build(tmp_path / "bad.h5", mutate, sweep=True)
    with pytest.raises(TraceFormatError, match=match) as info:
        read_trace(path)
    assert "bad.h5" in str(info.value)


LABEL_CASES: dict[str, tuple[Mutation, str]] = {
    "no force": (lambda f: f.__delitem__("labels/force_n"), "'labels/force_n'"),
    "force shape": (replace("labels/force_n", np.zeros(N + 1)), "'labels/force_n' must have"),
    "NaN force": (replace("labels/force_n", np.full(N, np.nan)), "labels.force_n must be finite"),
    "modal shape": (
        lambda f: f.create_dataset("labels/modal_m", data=np.zeros((2, N - 1))),
        "'labels/modal_m' must have shape \\('n_modes', 32\\)",
    ),
    "model not JSON": (set_attr("model", "{name: vdw", "labels"), "'labels/model' must be a JSON"),
    "scalar array on 1-D": (
        lambda f: f.create_dataset("labels/energy_j", data=np.ones(3)),
        "'labels/energy_j': a scalar must be 0-d",
    ),
    "labels is a dataset": (replace("labels", np.zeros(3)), "'labels' must be a group"),
}


@pytest.mark.parametrize("case", LABEL_CASES, ids=list(LABEL_CASES))
def test_malformed_labels_only_matter_when_asked(tmp_path: Path, case: str) -> None:
    mutate, match = LABEL_CASES[case]
    path = build(tmp_path / "bad.h5", mutate)
    assert read_trace(path).labels is None
    with pytest.raises(TraceFormatError, match=match) as info:
        read_trace(path, labels=True)
    assert "bad.h5" in str(info.value)


def test_unknown_entries_are_ignored(tmp_path: Path) -> None:
    """Version 1 may grow optional fields: readers skip what they do not know."""

    def add(f: h5py.File) -> None:
        f.attrs["operator"] = "someone"
        f["temperature_k"] = np.full(N, 300.0)

    assert read_trace(build(tmp_path / "a.h5", add)).n_samples == N
