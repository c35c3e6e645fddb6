"""Instrument files in: every real file (MIT copies in tests/data, GPL ones read from
../shared/data/real and skipped when absent), the column convention, calibration precedence
and units, and the hand-over from read_trace / Experiment.read."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from afmlearn.io import Experiment, read_trace
from afmlearn.io.instruments import (
    ForceCurve,
    RecordingError,
    convert_recording,
    open_recording,
    read_force_curve,
    reader_for,
)

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT / "tests" / "data"
SHARED = ROOT.parent / "shared" / "data" / "real"
ON = DATA / "asylum_am_approach_curves" / "AZ_0052.ibw"
OFF = DATA / "asylum_am_approach_curves" / "AZ_0101.ibw"
FORCE = DATA / "afmformats_forcecurves"
NID = DATA / "nanosurf_thermal_tune" / "thermal.nid"
JAM = SHARED / "freqdemod_skpfm_cantilever" / "JAM_9p90__copy.h5"


def test_asylum_ac_curve_calibration_segments_and_signs():
    t = open_recording(ON)
    assert t.is_curves and t.deflection_m is None
    # wave note: SpringConstant, ThermalQ, ThermalFrequency, DriveFrequency, NumPtsPerSec
    assert (t.spring_constant_n_per_m, t.quality_factor) == (2.6955, 187.36)
    assert t.resonance_frequency_hz == t.drive_frequency_hz == 72350.0
    assert t.sample_rate_hz == 2000.0
    # Indexes 0,1173,2180 with Direction NaN,1,-1: approach then retraction
    assert np.all(t.segment[:1173] == 0) and np.all(t.segment[1174:] == 1)
    approach = t.segment == 0
    # ZSnsr rises while extending towards the sample: z_piezo_m (= -ZSnsr) falls
    assert np.mean(np.diff(t.z_piezo_m[approach]) < 0) > 0.99
    assert np.mean(np.diff(t.z_piezo_m[~approach]) > 0) > 0.99
    # the tip met the surface: amplitude drops towards the closest approach
    closest = int(np.argmin(t.z_piezo_m))
    assert t.amplitude_m[closest] < 0.7 * np.median(t.amplitude_m[:100])
    # far from the surface the lag is ~pi/2 (Asylum's 90 deg at free resonance, 85 deg here)
    assert abs(np.median(t.phase_rad[:100]) - math.pi / 2) < math.radians(10)
    # metres: a tapping amplitude of tens of nm
    assert 1e-9 < np.median(t.amplitude_m[:100]) < 1e-6
    assert np.min(t.gap_m) == 0.0 and "offset is unknown" in t.description


def _fake_dual_ac_wave(amp2: np.ndarray, note: str) -> dict:
    """A DualAC wave as igor2 returns it: columns Raw, Amp, Phase, Amp2, Phas2, ZSnsr."""
    n = amp2.size
    z = np.linspace(0.0, 200e-9, n)
    data = np.column_stack([z, np.full(n, 0.3), np.full(n, 90.0), amp2,
                            np.linspace(80.0, 100.0, n), z])
    labels = [b"", b"Raw", b"Amp", b"Phase", b"Amp2", b"Phas2", b"ZSnsr"]
    return {"wave": {"wData": data, "labels": [[], labels],
                     "note": note.encode(), "wave_header": {"sfA": [5e-4]}}}


@pytest.mark.parametrize(("amp2_v", "inv2", "expect_m"), [
    (0.05, "Amp2InvOLS: 2e-08\r", 1e-9),   # volts x the second mode's own sensitivity
    (2e-9, "", 2e-9),                       # already in metres
    (0.05, "", None),                       # volts without Amp2InvOLS: left out, no guess
])
def test_asylum_bimodal_amp2_phas2_become_the_second_lockin(monkeypatch, tmp_path, amp2_v,
                                                              inv2, expect_m):
    import igor2.binarywave

    note = ("SpringConstant: 2\rThermalQ: 200\rThermalFrequency: 70000\r"
            "DriveFrequency: 70000\rDriveFrequency1: 440000\rNumPtsPerSec: 2000\r"
            "AmpInvOLS: 1e-07\r" + inv2)
    wave = _fake_dual_ac_wave(np.full(64, amp2_v), note)
    monkeypatch.setattr(igor2.binarywave, "load", lambda _path: wave)
    path = tmp_path / "dual.ibw"
    path.write_bytes(b"stand-in: the loader is patched")
    t = open_recording(path)
    np.testing.assert_allclose(t.amplitude_m, 0.3 * 1e-7)
    if expect_m is None:
        assert t.amplitude2_m is None and t.phase2_rad is None and t.drive_frequency2_hz is None
        return
    np.testing.assert_allclose(t.amplitude2_m, expect_m)
    np.testing.assert_allclose(t.phase2_rad, np.radians(np.linspace(80.0, 100.0, 64)))
    assert t.drive_frequency2_hz == 440000.0
    written = convert_recording(path, tmp_path / "dual.h5")
    back = read_trace(written[0]["path"])
    np.testing.assert_allclose(back.amplitude2_m, expect_m)
    assert back.drive_frequency2_hz == 440000.0


def test_asylum_off_surface_curve_stays_free():
    t = open_recording(OFF)
    assert t.amplitude_m.min() > 0.9 * t.amplitude_m.max()  # never touched the surface
    assert np.ptp(t.phase_rad) < math.radians(5)


def test_asylum_static_force_curve():
    c = open_recording(FORCE / "fmt-igor-fd_SiN_FD_plot.ibw")
    assert isinstance(c, ForceCurve)
    assert c.spring_constant_n_per_m == 1.1841 and c.invols_m_per_v == pytest.approx(44.99e-9)
    np.testing.assert_allclose(c.force_n, -c.spring_constant_n_per_m * c.deflection_m)
    closest = int(np.argmin(c.z_piezo_m))
    assert c.force_n[closest] > 0  # pressed into the sample: repulsive
    assert np.bincount(c.segment).tolist() == [1008, 1008]


def test_jpk_force_curve():
    c = open_recording(FORCE / "fmt-jpk-fd_spot3-0192.jpk-force")
    assert c.spring_constant_n_per_m == pytest.approx(0.043494, rel=1e-4)
    assert c.n_points == 4000 and np.bincount(c.segment).tolist() == [2000, 2000]
    assert c.force_n[int(np.argmin(c.z_piezo_m))] > 0
    np.testing.assert_allclose(c.deflection_m, -c.force_n / c.spring_constant_n_per_m)


def test_afm_workshop_csv_force_curve_without_spring_constant(tmp_path):
    path = FORCE / "fmt-afm-workshop-fd_single_2021-10-22_14.16.csv"
    assert type(reader_for(path)).__name__ == "AfmformatsReader"
    c = open_recording(path)
    assert c.spring_constant_n_per_m is None and c.deflection_m is None
    assert c.n_points == 2434
    out = convert_recording(path, tmp_path / "curve.h5")
    assert out[0]["kind"] == "force_curve"
    back = read_force_curve(tmp_path / "curve.h5")
    np.testing.assert_array_equal(back.force_n, c.force_n)


def test_nanosurf_thermal_tune_header_and_not_a_trace():
    parsed = reader_for(NID).parse(NID)[0]
    h = parsed.header
    assert (h["vendor_resonance_frequency_hz"], h["vendor_quality_factor"],
            h["vendor_spring_constant_n_per_m"]) == (179.8e3, 442.0, 27.13)
    assert h["n_averages"] == 1000 and h["temperature_k"] == pytest.approx(313.15)
    assert h["fit_range_hz"] == (114e3, 266e3)
    f = parsed.arrays["frequency_hz"]
    assert f.size == 8369 and np.diff(f).mean() == pytest.approx(38.147, rel=1e-4)
    with pytest.raises(RecordingError, match="thermal spectrum"):
        open_recording(NID)


@pytest.mark.skipif(not JAM.is_file(), reason=f"GPL data not present: {JAM}")
def test_plain_hdf5_deflection_series_with_user_calibration():
    calibration = dict(sample_rate_hz=1.15e6, spring_constant_n_per_m=3.0, quality_factor=1e4,
                       resonance_frequency_hz=60.63e3, drive_frequency_hz=60.63e3, gap_m=50e-9)
    with pytest.raises(RecordingError, match="column=NAME unit=UNIT"):
        open_recording(JAM, **calibration)
    t = open_recording(JAM, column="s", unit="nm", **calibration)
    assert t.n_samples == 762_375
    spectrum = np.abs(np.fft.rfft(t.deflection_m - t.deflection_m.mean()))
    peak = np.fft.rfftfreq(t.n_samples, 1 / t.sample_rate_hz)[np.argmax(spectrum)]
    assert peak == pytest.approx(60.63e3, rel=1e-3)  # the package's notebook: ~60.63 kHz
    missing = dict(calibration)
    missing.pop("quality_factor")
    with pytest.raises(RecordingError, match="'quality_factor'.*quality_factor=VALUE"):
        open_recording(JAM, column="s", unit="nm", **missing)


def _csv(path: Path, header: str, columns: dict[str, np.ndarray]) -> Path:
    names = ",".join(columns)
    rows = np.column_stack(list(columns.values()))
    np.savetxt(path, rows, delimiter=",", header=header + names, comments="")
    return path


CAL = ("# sample_rate_hz: 1e6\n# spring_constant_n_per_m: 40\n# quality_factor: 400\n"
       "# resonance_frequency_hz: 300e3\n# drive_frequency_hz: 300e3\n")


def test_csv_and_npz_convention_units_and_kinds(tmp_path):
    x_nm = 20 * np.sin(2 * np.pi * 0.3 * np.arange(400))
    t = open_recording(_csv(tmp_path / "a.csv", CAL + "# gap_m: 30e-9\n",
                            {"deflection_nm": x_nm}))
    np.testing.assert_allclose(t.deflection_m, x_nm * 1e-9)
    assert (t.sample_rate_hz, t.gap_m, t.quality_factor) == (1e6, 30e-9, 400.0)
    # lock-in curves: degrees -> radians, nm -> m, segment kept
    z = np.linspace(50, 0, 200)
    curves = {"z_piezo_nm": z, "amplitude_nm": np.minimum(z, 20.0),
              "phase_deg": np.full(200, 90.0), "segment": np.zeros(200)}
    lock = open_recording(_csv(tmp_path / "b.csv", CAL, curves))
    assert lock.is_curves and np.allclose(lock.phase_rad, math.pi / 2)
    np.testing.assert_allclose(lock.z_piezo_m, z * 1e-9)
    npz = tmp_path / "c.npz"
    np.savez(npz, deflection_v=x_nm / 50.0, sample_rate_hz=1e6, spring_constant_n_per_m=40.0,
             quality_factor=400.0, resonance_frequency_hz=300e3, drive_frequency_hz=300e3,
             gap_m=30e-9)
    with pytest.raises(RecordingError, match="invols_m_per_v"):
        open_recording(npz)
    t2 = open_recording(npz, invols_m_per_v=50e-9)
    np.testing.assert_allclose(t2.deflection_m, x_nm * 1e-9)


def test_wrong_units_and_missing_calibration_are_one_line(tmp_path):
    big = _csv(tmp_path / "big.csv", CAL + "# gap_m: 30e-9\n", {"deflection_m": np.full(50, 20.0)})
    with pytest.raises(RecordingError, match="not a length an AFM records in metres") as err:
        open_recording(big)
    assert "\n" not in str(err.value)
    odd = _csv(tmp_path / "odd.csv", CAL, {"deflection_s": np.zeros(50)})
    with pytest.raises(RecordingError, match="does not fit deflection"):
        open_recording(odd)
    bare = _csv(tmp_path / "bare.csv", "# sample_rate_hz: 1e6\n", {"deflection_nm": np.zeros(50)})
    with pytest.raises(RecordingError, match="missing calibration 'spring_constant_n_per_m'"
                       r".*calibration=calibration.json \(scripts/calibrate.py\)"):
        open_recording(bare)
    # a thermal calibration.json cannot give the drive: the message does not send you there
    thermal = {"resonance_frequency_hz": 3e5, "quality_factor": 400.0,
               "spring_constant_n_per_m": 40.0}
    no_drive = _csv(tmp_path / "no_drive.csv", "# gap_m: 30e-9\n",
                    {"time_us": np.arange(50.0), "deflection_nm": np.zeros(50)})
    with pytest.raises(RecordingError, match="missing calibration 'drive_frequency_hz'") as err:
        open_recording(no_drive, calibration=thermal)
    assert "calibration.json" not in str(err.value) and "# drive_frequency_hz:" in str(err.value)
    # read as an entry point's trace= (no way to pass calibration there): convert first
    with pytest.raises(RecordingError, match=r"convert it with the value first, `python "
                       r"scripts/convert.py input=.*bare.csv output=trace.h5 "
                       r"spring_constant_n_per_m=VALUE` \(or calibration=") as err:
        read_trace(bare)
    assert "\n" not in str(err.value)


def test_defaults_fill_only_what_the_file_does_not_state(tmp_path):
    path = _csv(tmp_path / "d.csv", CAL + "# gap_m: 30e-9\n", {"deflection_nm": np.zeros(50)})
    t = open_recording(path, defaults={"sample_rate_hz": 2e6, "tip_radius_m": 7e-9})
    assert t.sample_rate_hz == 1e6 and t.tip_radius_m == 7e-9      # file wins; gap filled
    t = open_recording(path, defaults={"sample_rate_hz": 2e6}, sample_rate_hz=3e6)
    assert t.sample_rate_hz == 3e6                                   # an override wins
    with pytest.raises(RecordingError, match="unknown override"):
        open_recording(path, defaults={"colour": 1})


def test_calibration_precedence_file_json_override(tmp_path):
    cal = tmp_path / "calibration.json"
    cal.write_text(json.dumps({"quality_factor": 200.0, "quality_factor_interval": [190, 210],
                               "spring_constant_n_per_m": 2.5}))
    t = open_recording(ON, calibration=cal)
    assert (t.quality_factor, t.spring_constant_n_per_m) == (200.0, 2.5)
    assert t.resonance_frequency_hz == 72350.0  # not in the json: the file's
    t = open_recording(ON, calibration=cal, quality_factor=250.0)
    assert t.quality_factor == 250.0
    with pytest.raises(RecordingError, match="unknown override"):
        open_recording(ON, spring_constant=1.0)


def test_read_trace_and_experiment_accept_instrument_files(tmp_path):
    t = read_trace(ON)
    assert t.is_curves and t.spring_constant_n_per_m == 2.6955
    exp = Experiment.read(ON)
    assert len(exp) == 1 and exp.kind == "curves"
    with pytest.raises(RecordingError, match="static force curve.*analyze_force_curve.py curve="):
        read_trace(FORCE / "fmt-jpk-fd_spot3-0192.jpk-force")
    # the converted file is a trace-format-v1 file holding the same lock-in curve
    convert_recording(ON, tmp_path / "on.h5")
    back = read_trace(tmp_path / "on.h5")
    for name in ("amplitude_m", "phase_rad", "z_piezo_m", "segment", "gap_m"):
        np.testing.assert_array_equal(getattr(back, name), getattr(t, name))
    assert back.lockin_bandwidth_hz == t.lockin_bandwidth_hz == 1000.0


NCAFM = SHARED / "ncafm_fm_spectroscopy" / "all_data_dataframe_237K.csv"


@pytest.mark.skipif(not NCAFM.is_file(), reason=f"GPL data not present: {NCAFM}")
def test_fm_spectroscopy_table_is_refused_with_one_clear_line():
    """Δf(z) tables (FM-AFM) are no trace-format kind: one line saying what a CSV must be."""
    with pytest.raises(RecordingError, match="neither a table of the column convention") as err:
        open_recording(NCAFM)
    assert "\n" not in str(err.value)
