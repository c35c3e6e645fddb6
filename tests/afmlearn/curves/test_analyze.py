"""The folder batch: a bad file, a crash and a timeout are recorded, never stop it; a second
run resumes from the reports already written."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

from afmlearn.curves import EXTENSIONS, Curve, CurveDiagnoser, CurveLaw
from afmlearn.curves.analyze import analyze_folder, damping_terms_si
from afmlearn.simulate import simulate

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """good/a.h5, good/b.h5 (a simulated curve) and bad/junk.h5 (not HDF5)."""
    base = tmp_path_factory.mktemp("batch")
    (base / "good").mkdir()
    (base / "bad").mkdir()
    GlobalHydra.instance().clear()
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        cfg = compose("simulate", overrides=["scenario=lockin", "scenario.n_periods=400",
                                             "excitation.free_amplitude_ratio=1.5",
                                             "progress=false", f"output={base}/good/a.h5"])
    simulate(cfg)
    shutil.copy(base / "good" / "a.h5", base / "good" / "b.h5")
    (base / "bad" / "junk.h5").write_bytes(b"not an hdf5 file")
    return base


def quick() -> CurveDiagnoser:
    return CurveDiagnoser(hypotheses=EXTENSIONS[:1], max_nfev=2)


def test_batch_records_errors_and_resumes(folder, tmp_path):
    out = tmp_path / "out"
    s1 = analyze_folder(folder, out, make_diagnoser=quick, time_limit_s=300)
    rows = {r["file"]: r for r in s1["curves"]}
    assert set(rows) == {"bad/junk.h5", "good/a.h5", "good/b.h5"}
    assert "error" in rows["bad/junk.h5"] and rows["bad/junk.h5"]["group"] == "bad"
    assert s1["n_analysed"] == 2 and rows["good/a.h5"]["seconds"] > 0
    # identical files, identical fits (the child process is deterministic)
    assert rows["good/a.h5"]["heldout_nrmse_baseline"] == rows["good/b.h5"][
        "heldout_nrmse_baseline"]
    report = out / "good" / "a" / "report.json"
    # the damping terms in SI (none: the only hypothesis tried here is the contact exponent)
    assert json.loads(report.read_text())["curve"]["damping_terms"] == []
    stamp = report.stat().st_mtime_ns
    s2 = analyze_folder(folder, out, make_diagnoser=quick, time_limit_s=300)
    assert report.stat().st_mtime_ns == stamp  # read back, not redone
    assert json.dumps(s2["curves"]) == json.dumps(s1["curves"])


def test_batch_records_a_timeout_and_a_crash(folder, tmp_path):
    s = analyze_folder(folder / "good", tmp_path / "t", make_diagnoser=quick,
                       time_limit_s=0.05)
    assert all(r["error"] == "timeout after 0.05 s" for r in s["curves"])

    def crash() -> CurveDiagnoser:
        raise RuntimeError("boom")

    s = analyze_folder(folder / "good", tmp_path / "c", make_diagnoser=crash, time_limit_s=60)
    assert all(r["error"] == "RuntimeError: boom" for r in s["curves"])
    with pytest.raises(ValueError, match="time_limit_s"):
        analyze_folder(folder, tmp_path / "x", time_limit_s=0.0)


def test_group_summary_counts_agreement_and_gains():
    from afmlearn.curves.analyze import group_summary

    rows = ([{"cause": "long_range_damping", "gain": g, "seconds": 10.0, "load": 2.0}
             for g in (0.1, 0.3, -0.05)]
            + [{"cause": "none", "gain": 0.0, "seconds": 30.0, "load": 4.0},
               {"error": "timeout after 30 s"}])
    s = group_summary(rows)
    assert s["n"] == 5 and s["errors"] == 1
    assert s["majority"] == "long_range_damping" and s["agreement"] == pytest.approx(0.75)
    assert s["n_named"] == 3 and s["gain_positive"] == pytest.approx(2 / 3)
    assert s["median_gain"] == pytest.approx(0.1)
    assert s["seconds"] == [10.0, 30.0] and s["load"] == 2.0


def test_damping_terms_in_si():
    """Both damping terms of a law in SI: N s/m = c k / omega0, length = z_b L, and the ratio
    to the lever's own damping k / (omega0 Q) is c Q; a term that is off is left out."""
    curve = Curve(tau=np.arange(3.0), amplitude=np.ones(3), phase=np.full(3, math.pi / 2),
                  z_piezo=np.array([3.0, 2.0, 1.0]), segment=np.zeros(3, dtype=np.int8),
                  quality_factor=200.0, spring_constant_n_per_m=2.0,
                  resonance_frequency_hz=7e4, length_m=20e-9, drive_frequency_hz=7e4)
    law = CurveLaw(a0=0.015, damping=1e-2, decay_length=0.05, far_damping=2.5e-4,
                   far_decay_length=25.0)
    near, far = damping_terms_si(law, curve)
    w0 = 2 * math.pi * 7e4
    assert near["term"] == "near" and far["term"] == "far"
    assert near["coefficient_n_s_per_m"] == pytest.approx(1e-2 * 2.0 / w0)
    assert near["decay_length_m"] == pytest.approx(1e-9)
    assert far["decay_length_m"] == pytest.approx(500e-9)
    assert far["times_lever_damping"] == pytest.approx(0.05)
    # the lever's own damping k / (omega0 Q) in N s/m, the ratio's reference
    assert far["coefficient_n_s_per_m"] / far["times_lever_damping"] == pytest.approx(
        2.0 / (w0 * 200.0))
    assert [t["term"] for t in damping_terms_si(law.replace(damping=0.0), curve)] == ["far"]
