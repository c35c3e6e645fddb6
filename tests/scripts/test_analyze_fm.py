"""scripts/analyze_fm.py: a small synthetic Δf(z, V) map (sidecar calibration) analysed end to
end; bad input (missing calibration, damaged table) is one `error:` line and exit status 2;
and, when present, the real nc_AFM map (GPL-3.0, ../shared/data/real; slow)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from afmlearn.fm import FMLaw, FMSpectroscopy, model_hz

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "analyze_fm.py"
REAL = ROOT.parent / "shared" / "data" / "real" / "ncafm_fm_spectroscopy"
CAL = {"spring_constant_n_per_m": 1800.0, "amplitude_m": 0.5e-9,
       "resonance_frequency_hz": 19796.5}
TRUE = FMLaw(hamaker_j=0.0, modulus_pa=0.0, tip_radius_m=5e-9, vcpd_v=1.75,
             es_radius_m=80e-9, es_setback_m=3e-9, far_gradient_n_per_m_v2=3e-3,
             far_vcpd_v=0.5, z_contact_m=-30.5e-9, offset_hz=-0.2)


def write_map(folder: Path, *, calibration: bool = True) -> Path:
    z = -28e-9 + 0.8e-9 * np.arange(16)
    bias = np.linspace(10.0, -10.0, 17)
    df = model_hz(FMSpectroscopy(np.zeros((z.size, bias.size)), z, bias, **CAL), TRUE)
    df = df + np.random.default_rng(1).normal(0.0, 1.0 / 6.0, df.shape)
    folder.mkdir(parents=True)
    lines = ["," + ",".join(repr(float(v)) for v in bias)]
    lines += [f"{i}," + ",".join(repr(float(x)) for x in row) for i, row in enumerate(df)]
    (folder / "df_dataframe_syn.csv").write_text("\n".join(lines) + "\n")
    (folder / "z_piezo.csv").write_text("\n".join(repr(float(x)) for x in z) + "\n")
    if calibration:
        (folder / "fm_calibration.json").write_text(json.dumps(CAL))
    return folder


def run(tmp_path: Path, *args: str, timeout: int = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *args], cwd=tmp_path,
                          capture_output=True, text=True, timeout=timeout)


@pytest.mark.slow  # ~12 s CPU (six fits, a profile and figures)
def test_synthetic_map_end_to_end(tmp_path):
    data = write_map(tmp_path / "map")
    out = tmp_path / "out"
    proc = run(tmp_path, f"data={data}", f"out_dir={out}", "exclude_closest_m=0",
               "window_variants_m=[]", "profile_points=5", "figures=true", "jackknife_blocks=3")
    assert proc.returncode == 0, proc.stderr[-2000:]
    rep = json.loads((out / "report.json").read_text())
    assert rep["cause"] == "electrostatic"
    assert rep["extended"]["heldout_rms_hz"] < 0.5 * rep["baseline"]["heldout_rms_hz"]
    assert rep["vcpd"]["value_v"] == pytest.approx(1.75, abs=0.1)
    lo, hi = rep["vcpd"]["jackknife"]["interval_95_v"]
    assert lo - 0.05 < 1.75 < hi + 0.05
    assert all((out / f).is_file() for f in rep["figures"]) and len(rep["figures"]) == 3
    assert "V_cpd (apex)" in proc.stdout


def test_missing_calibration_exits_2_with_one_line(tmp_path):
    data = write_map(tmp_path / "map", calibration=False)
    proc = run(tmp_path, f"data={data}", f"out_dir={tmp_path / 'out'}", timeout=120)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") \
        and "spring_constant_n_per_m" in lines[0]


def test_damaged_table_exits_2_with_one_line(tmp_path):
    data = write_map(tmp_path / "map")
    table = data / "df_dataframe_syn.csv"
    text = table.read_text()
    table.write_text(text[: len(text) // 2])  # truncated mid-row
    proc = run(tmp_path, f"data={data}", f"out_dir={tmp_path / 'out'}", timeout=120)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and "truncated" in lines[0]


@pytest.mark.slow
@pytest.mark.skipif(not REAL.is_dir(), reason=f"nc_AFM example data (GPL-3.0) not at {REAL}")
def test_real_map_names_electrostatics_and_a_cpd_near_the_authors(tmp_path):
    out = tmp_path / "out"
    proc = run(tmp_path, f"data={REAL}", f"out_dir={out}", "spring_constant_n_per_m=1800",
               "amplitude_m=0.5e-9", "resonance_frequency_hz=19796.5", "window_variants_m=[]",
               "profile_points=5", "figures=false", "jackknife_blocks=0", timeout=1800)
    assert proc.returncode == 0, proc.stderr[-2000:]
    rep = json.loads((out / "report.json").read_text())
    assert rep["cause"] == "electrostatic" and rep["gain"] > 0.5
    assert 1.2 < rep["vcpd"]["value_v"] < 2.3  # authors: 1.75 V
