"""The readers on files we have not seen: variants of the real files (another Igor wave
version, wave notes with keys missing or renamed, other channel sets, channels in volts, a
JPK dwell segment, an uncalibrated JPK curve, CSV exports with other separators, decimal
commas, a byte-order mark, units in brackets). Each is read correctly or refused with one
line naming what is missing (docs/recordings.md, "Variants")."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from afmlearn.io.instruments import ForceCurve, RecordingError, open_recording, reader_for
from afmlearn.io.instruments.errors import MissingCalibration
from afmlearn.io.instruments.table import CsvReader

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT / "tests" / "data"
ON = DATA / "asylum_am_approach_curves" / "AZ_0052.ibw"
STATIC = DATA / "afmformats_forcecurves" / "fmt-igor-fd_SiN_FD_plot.ibw"
JPK = DATA / "afmformats_forcecurves" / "fmt-jpk-fd_spot3-0192.jpk-force"

_spec = importlib.util.spec_from_file_location("variant_files",
                                               Path(__file__).with_name("variant_files.py"))
V = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(V)


def _one_line(err: pytest.ExceptionInfo) -> str:
    text = str(err.value)
    assert "\n" not in text and "Traceback" not in text
    return text


# --- Asylum .ibw: wave versions ----------------------------------------------------------

def test_version2_single_channel_wave_is_refused_naming_version_and_labels(tmp_path):
    path = V.ibw_version2(tmp_path / "defl_v2.ibw", np.linspace(0.0, 1e-8, 50))
    with pytest.raises(RecordingError) as err:
        open_recording(path)
    line = _one_line(err)
    assert "version 2" in line and "'Defl'" in line and "labelled" in line, line
    assert "corrupted" not in line  # a valid file of another version, not damage


def test_version5_note_rewrite_keeps_the_real_file_readable(tmp_path):
    """The byte-level note editor itself: an unchanged note reads as the original."""
    same = V.ibw_with_note(ON, tmp_path / "same.ibw", lambda note: note)
    a, b = open_recording(ON), open_recording(same)
    np.testing.assert_array_equal(a.amplitude_m, b.amplitude_m)
    assert (a.quality_factor, a.sample_rate_hz) == (b.quality_factor, b.sample_rate_hz)


# --- Asylum .ibw: wave-note keys missing or renamed ----------------------------------------

@pytest.mark.parametrize(("key", "field"), [
    ("ThermalFrequency", "resonance_frequency_hz"),
    ("ThermalQ", "quality_factor"),
    ("SpringConstant", "spring_constant_n_per_m"),
    ("DriveFrequency", "drive_frequency_hz"),
])
def test_missing_note_key_names_the_field_and_an_override_completes_it(tmp_path, key, field):
    path = V.ibw_with_note(ON, tmp_path / f"no_{key}.ibw", V.drop_note_keys(key))
    with pytest.raises(MissingCalibration) as err:
        open_recording(path)
    assert err.value.field == field and f"{field}=VALUE" in _one_line(err)
    value = {"quality_factor": 150.0, "spring_constant_n_per_m": 3.0}.get(field, 71000.0)
    trace = open_recording(path, **{field: value})
    assert getattr(trace, field) == value
    # the other note values are still the file's
    full = open_recording(ON)
    for other in ("quality_factor", "spring_constant_n_per_m", "sample_rate_hz"):
        if other != field:
            assert getattr(trace, other) == getattr(full, other)


def test_renamed_resonance_key_is_not_guessed_from_another_frequency(tmp_path):
    """DriveFrequency is where the lever was driven, not its resonance: a note with only
    'ResFreq1' / 'DriveFrequency' (no ThermalFrequency) must not take either as f0."""
    path = V.ibw_with_note(ON, tmp_path / "renamed.ibw",
                           lambda n: n.replace("\rThermalFrequency:", "\rThermalFreq:"))
    with pytest.raises(MissingCalibration) as err:
        open_recording(path)
    assert err.value.field == "resonance_frequency_hz"


def test_zero_or_nan_calibration_in_the_note_counts_as_missing(tmp_path):
    path = V.ibw_with_note(ON, tmp_path / "q0.ibw", V.set_note_keys(ThermalQ="0",
                                                                     SpringConstant="NaN"))
    with pytest.raises(MissingCalibration) as err:
        open_recording(path)
    assert err.value.field in ("quality_factor", "spring_constant_n_per_m")


def test_without_numptspersec_the_rate_comes_from_the_wave_scaling(tmp_path):
    """The row scaling sfA[0] = 5e-4 s of the real wave gives 2000 Hz, as NumPtsPerSec."""
    path = V.ibw_with_note(ON, tmp_path / "norate.ibw", V.drop_note_keys("NumPtsPerSec"))
    assert open_recording(path).sample_rate_hz == pytest.approx(2000.0)


def test_without_indexes_the_curve_is_one_segment(tmp_path):
    path = V.ibw_with_note(ON, tmp_path / "noidx.ibw", V.drop_note_keys("Indexes",
                                                                         "Direction"))
    assert np.all(open_recording(path).segment == 0)


def test_dwell_segment_goes_with_the_approach(tmp_path):
    """Indexes 0,1000,1173,2180 with Direction NaN,1,0,-1: extend, dwell, retract."""
    path = V.ibw_with_note(ON, tmp_path / "dwell.ibw",
                           V.set_note_keys(Indexes="0,1000,1173,2180", Direction="NaN,1,0,-1,"))
    seg = open_recording(path).segment
    assert np.all(seg[:1173] == 0) and np.all(seg[1174:] == 1)  # 1173: the turning point


def test_unreadable_indexes_is_one_line(tmp_path):
    path = V.ibw_with_note(ON, tmp_path / "badidx.ibw", V.set_note_keys(Indexes="0,a,b"))
    with pytest.raises(RecordingError) as err:
        open_recording(path)
    assert "Indexes/Direction" in _one_line(err)


def test_amp_in_metres_needs_no_ampinvols(tmp_path):
    path = V.ibw_with_note(ON, tmp_path / "noamp.ibw", V.drop_note_keys("AmpInvOLS",
                                                                         "InvOLS"))
    np.testing.assert_array_equal(open_recording(path).amplitude_m,
                                  open_recording(ON).amplitude_m)


# --- Asylum .ibw: other channel sets (the real wave with columns dropped or in volts) ------

def _patched(monkeypatch, tmp_path, wave, name="x.ibw") -> Path:
    import igor2.binarywave

    monkeypatch.setattr(igor2.binarywave, "load", lambda _path: wave)
    path = tmp_path / name
    path.write_bytes(b"stand-in: the loader is patched")
    return path


def test_without_zsnsr_the_raw_z_is_used(monkeypatch, tmp_path):
    full = open_recording(ON)
    from igor2 import binarywave

    raw = np.asarray(binarywave.load(str(ON))["wave"]["wData"], dtype=float)[:, 0]
    t = open_recording(_patched(monkeypatch, tmp_path, V.edited_wave(ON, drop=("ZSnsr",))))
    np.testing.assert_allclose(t.z_piezo_m, -raw)
    np.testing.assert_array_equal(t.amplitude_m, full.amplitude_m)


def test_only_defl_is_refused_naming_the_z_columns(monkeypatch, tmp_path):
    wave = V.edited_wave(STATIC, drop=("Raw", "ZSnsr"))
    with pytest.raises(RecordingError) as err:
        open_recording(_patched(monkeypatch, tmp_path, wave))
    line = _one_line(err)
    assert "ZSnsr or Raw" in line and "['Defl']" in line, line


def test_z_sensor_in_volts_is_refused(monkeypatch, tmp_path):
    wave = V.edited_wave(ON, scale={"ZSnsr": 1e7})  # ~7 V
    with pytest.raises(RecordingError) as err:
        open_recording(_patched(monkeypatch, tmp_path, wave))
    assert "ZSnsr" in _one_line(err) and "volts" in str(err.value)


def test_amp_in_volts_without_ampinvols_is_refused_naming_it(monkeypatch, tmp_path):
    """Amp stored in volts (the controller's raw channel) and a note without AmpInvOLS:
    refused naming AmpInvOLS, not taken as metres nor as a wrong-unit column."""
    note_src = V.ibw_with_note(ON, tmp_path / "n.ibw", V.drop_note_keys("AmpInvOLS"))
    wave = V.edited_wave(note_src, scale={"Amp": 1.0 / 7.1685e-08})
    with pytest.raises(RecordingError) as err:
        open_recording(_patched(monkeypatch, tmp_path, wave))
    assert "AmpInvOLS" in _one_line(err), str(err.value)


def test_amp_in_volts_with_ampinvols_is_scaled_to_metres(monkeypatch, tmp_path):
    full = open_recording(ON)
    wave = V.edited_wave(ON, scale={"Amp": 1.0 / 7.1685e-08})
    t = open_recording(_patched(monkeypatch, tmp_path, wave))
    np.testing.assert_allclose(t.amplitude_m, full.amplitude_m, rtol=1e-6)


def test_defl_in_volts_without_invols_is_refused_and_the_override_reads_it(monkeypatch,
                                                                           tmp_path):
    full = open_recording(STATIC)
    invols = 4.499e-08
    note_src = V.ibw_with_note(STATIC, tmp_path / "n.ibw", V.drop_note_keys("InvOLS"))
    wave = V.edited_wave(note_src, scale={"Defl": 1.0 / invols})
    path = _patched(monkeypatch, tmp_path, wave)
    with pytest.raises(RecordingError) as err:
        open_recording(path)
    assert "invols_m_per_v=VALUE" in _one_line(err), str(err.value)
    curve = open_recording(path, invols_m_per_v=invols)
    assert isinstance(curve, ForceCurve) and curve.invols_m_per_v == invols
    np.testing.assert_allclose(curve.force_n, full.force_n, rtol=1e-6, atol=1e-15)


def test_phase_without_amp_falls_back_to_the_static_curve(monkeypatch, tmp_path):
    """Amp dropped from an AC curve that also has Defl: not a lock-in curve, read as the
    static deflection curve (k Defl)."""
    from igor2 import binarywave

    loaded = binarywave.load(str(STATIC))
    wave = dict(loaded["wave"])
    data = np.asarray(wave["wData"], dtype=float)
    wave["wData"] = np.column_stack([data, np.full(data.shape[0], 90.0)])
    wave["labels"] = [[], [*wave["labels"][1], b"Phase"]]
    curve = open_recording(_patched(monkeypatch, tmp_path, {**loaded, "wave": wave}))
    assert isinstance(curve, ForceCurve)
    np.testing.assert_allclose(curve.force_n, open_recording(STATIC).force_n)


# --- JPK through afmformats ------------------------------------------------------------------

def test_jpk_dwell_segment_is_kept_with_the_approach(tmp_path):
    path = V.jpk_with_dwell(JPK, tmp_path / "creep.jpk-force")
    curve = open_recording(path)
    base = open_recording(JPK)
    assert curve.n_points == 6000 and np.bincount(curve.segment).tolist() == [4000, 2000]
    # the retraction is the original one, the approach unchanged
    np.testing.assert_array_equal(curve.force_n[4000:], base.force_n[2000:])
    np.testing.assert_array_equal(curve.force_n[:2000], base.force_n[:2000])
    assert curve.spring_constant_n_per_m == base.spring_constant_n_per_m


def test_uncalibrated_jpk_is_refused_naming_the_spring_constant(tmp_path):
    def no_force(_name: str, data: bytes) -> bytes:
        return b"\n".join(line for line in data.split(b"\n")
                          if b"conversion.force." not in line)

    path = V.jpk_edited(JPK, tmp_path / "nok.jpk-force", no_force)
    with pytest.raises(RecordingError) as err:
        open_recording(path)
    line = _one_line(err)
    assert "spring constant" in line and "corrupted" not in line, line


def test_jpk_without_the_measured_height_uses_the_piezo_height(tmp_path):
    """strainGaugeHeight absent (no closed-loop Z sensor): afmformats offers no 'height
    (measured)'; the piezo height is read as before."""
    def no_sensor(_name: str, data: bytes) -> bytes:
        lines = [line for line in data.split(b"\n") if b"channel.strainGaugeHeight" not in line]
        return b"\n".join(lines).replace(b"channels.list=height vDeflection strainGaugeHeight",
                                         b"channels.list=height vDeflection")

    path = V.jpk_edited(JPK, tmp_path / "nosensor.jpk-force", no_sensor, skip="strainGauge")
    curve = open_recording(path)
    np.testing.assert_array_equal(curve.z_piezo_m, open_recording(JPK).z_piezo_m)
    np.testing.assert_array_equal(curve.force_n, open_recording(JPK).force_n)


# --- CSV exports ----------------------------------------------------------------------------

def _table(n: int = 40) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) / 1000.0
    return t, 1e-9 * np.sin(2 * math.pi * 50.0 * t)


@pytest.mark.parametrize("variant", ["bom", "semicolon_decimal_comma", "tab", "brackets",
                                     "parentheses_micro", "crlf_trailing_separator",
                                     "quoted"])
def test_csv_export_variants_read_as_the_plain_table(tmp_path, variant):
    t, d = _table()
    rows = [(f"{a:.9g}", f"{b:.9g}") for a, b in zip(t * 1e3, d * 1e9, strict=True)]
    sep, header, newline, prefix, end = ",", "time_ms,deflection_nm", "\n", "", ""
    if variant == "bom":
        prefix = "\ufeff"
    elif variant == "semicolon_decimal_comma":
        sep, header = ";", "time_ms;deflection_nm"
        rows = [(a.replace(".", ","), b.replace(".", ",")) for a, b in rows]
    elif variant == "tab":
        sep, header = "\t", "time [ms]\tdeflection [nm]"
    elif variant == "brackets":
        header = "Time [ms],Deflection [nm]"
    elif variant == "parentheses_micro":
        header = "time (ms),deflection (µm)"
        rows = [(a, f"{float(b) * 1e-3:.9g}") for a, b in rows]
    elif variant == "crlf_trailing_separator":
        newline, end = "\r\n", ","
    elif variant == "quoted":
        header = '"time_ms","deflection_nm"'
    text = prefix + "# sample_rate_hz: 1000\n" + header + newline + newline.join(
        sep.join(r) + end for r in rows) + newline
    path = tmp_path / f"{variant}.csv"
    path.write_text(text, encoding="utf-8")
    assert isinstance(reader_for(path), CsvReader)
    parsed = CsvReader().parse(path)[0]
    assert parsed.kind == "deflection" and parsed.header["sample_rate_hz"] == 1000.0
    np.testing.assert_allclose(parsed.arrays["deflection_m"], d, rtol=1e-6, atol=1e-18)


def test_csv_with_a_unitless_header_is_refused_with_the_convention(tmp_path):
    path = tmp_path / "nounits.csv"
    path.write_text("time;deflection\n0,0;1,5\n0,1;1,6\n")
    with pytest.raises(RecordingError) as err:
        open_recording(path)
    assert "<quantity>_<unit>" in _one_line(err)


def test_csv_with_ragged_rows_is_one_line(tmp_path):
    path = tmp_path / "ragged.csv"
    path.write_text("time_s;deflection_nm\n0,0;1,5\n0,1\n")
    with pytest.raises(RecordingError) as err:
        open_recording(path, spring_constant_n_per_m=1.0)
    assert "numeric table" in _one_line(err) or "columns" in str(err.value)


# --- Nanosurf .nid ----------------------------------------------------------------------------

NID = DATA / "nanosurf_thermal_tune" / "thermal.nid"


def test_nid_with_a_frequency_sweep_group_first_reads_the_thermal_spectrum(tmp_path):
    """The spectrum's axis and unit come from its own data set, not the file's first one."""
    from afmlearn.io.instruments.nanosurf import NanosurfReader

    path = V.nid_with_sweep_first(NID, tmp_path / "sweep_first.nid")
    a, b = NanosurfReader().parse(NID)[0], NanosurfReader().parse(path)[0]
    np.testing.assert_array_equal(b.arrays["asd_m_per_rthz"], a.arrays["asd_m_per_rthz"])
    np.testing.assert_array_equal(b.arrays["frequency_hz"], a.arrays["frequency_hz"])
    assert b.header["vendor_resonance_frequency_hz"] == a.header["vendor_resonance_frequency_hz"]


def test_nid_without_a_thermal_spectrum_is_one_line(tmp_path):
    """A .nid whose only groups are not 'Spectrum FFT' (here renamed frames)."""
    raw = NID.read_bytes()
    end = raw.index(b"\n\r\n\r")
    head = raw[:end].replace(b"Frame=Spectrum FFT", b"Frame=Spec forward")
    path = tmp_path / "nofft.nid"
    path.write_bytes(head + raw[end:])
    with pytest.raises(RecordingError) as err:
        from afmlearn.io.instruments.nanosurf import NanosurfReader

        NanosurfReader().parse(path)
    assert "Spectrum FFT" in _one_line(err)
