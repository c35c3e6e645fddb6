"""scripts/convert.py on variants of the real files (tests/afmlearn/io/variant_files.py):
read, or exit status 2 with one line naming what is missing."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from afmlearn.io import read_trace

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
IBW = DATA / "asylum_am_approach_curves" / "AZ_0052.ibw"
JPK = DATA / "afmformats_forcecurves" / "fmt-jpk-fd_spot3-0192.jpk-force"

_spec = importlib.util.spec_from_file_location(
    "variant_files", ROOT / "tests" / "afmlearn" / "io" / "variant_files.py")
V = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(V)


def test_variants_that_cannot_be_read_exit_2_naming_what_is_missing(tmp_path, run_script):
    v2 = V.ibw_version2(tmp_path / "v2.ibw", np.linspace(0.0, 1e-8, 50))
    no_q = V.ibw_with_note(IBW, tmp_path / "noq.ibw", V.drop_note_keys("ThermalQ"))

    def no_force(_name: str, data: bytes) -> bytes:
        return b"\n".join(line for line in data.split(b"\n") if b"conversion.force." not in line)

    no_k = V.jpk_edited(JPK, tmp_path / "nok.jpk-force", no_force)
    for path, fragment in ((v2, "version 2"), (no_q, "quality_factor=VALUE"),
                           (no_k, "spring constant")):
        out = tmp_path / f"{path.stem}.h5"
        line = run_script.error_line("convert.py", f"input={path}", f"output={out}")
        assert fragment in line, line
        assert not out.exists()
    # the missing value given on the command line completes the file
    code, _, err = run_script("convert.py", f"input={no_q}", f"output={tmp_path / 'q.h5'}",
                              "quality_factor=180")
    assert code == 0, err
    assert read_trace(tmp_path / "q.h5").quality_factor == 180.0


def test_semicolon_decimal_comma_csv_converts(tmp_path, run_script):
    t = np.arange(64) / 1e6
    d = 2e-9 * np.cos(2 * np.pi * 3e5 * t)
    rows = "\n".join(f"{a:.9g};{b:.9g}".replace(".", ",") for a, b in zip(t * 1e6, d * 1e9,
                                                                           strict=True))
    path = tmp_path / "export.csv"
    path.write_text("\ufefftime [us];deflection [nm]\n" + rows + "\n", encoding="utf-8")
    code, out, err = run_script(
        "convert.py", f"input={path}", f"output={tmp_path / 'c.h5'}",
        "spring_constant_n_per_m=40", "quality_factor=400", "resonance_frequency_hz=3e5",
        "drive_frequency_hz=3e5", "gap_m=1e-8")
    assert code == 0, err
    trace = read_trace(tmp_path / "c.h5")
    assert trace.sample_rate_hz == pytest.approx(1e6)
    np.testing.assert_allclose(trace.deflection_m, d, rtol=1e-6, atol=1e-18)
