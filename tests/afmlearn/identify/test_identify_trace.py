"""afmlearn.identify.infer.identify_trace: outputs aligned with the input, never reading /labels."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from afmlearn.identify.identifier import LINEAR_TERMS, ForceIdentifier
from afmlearn.identify.infer import identify_trace, jsonable
from afmlearn.identify.model import IdentifiedModel
from afmlearn.io import Trace, read_trace, write_trace
from afmlearn.plots.identify import identify_figures
from afmlearn.preprocess import calibrate
from afmlearn.simulate import simulate

ROOT = Path(__file__).resolve().parents[3]
#: a short, lightly noisy tapping trace: 30 periods x 100 samples
SMALL = ["scenario.n_periods=30", "scenario.samples_per_period=100", "noise.level=0.005",
         "free_trace_periods=5", "progress=false"]


def small_trace(path: Path, *overrides: str) -> Path:
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        cfg = compose("simulate", overrides=[*SMALL, f"output={path}", *overrides])
    simulate(cfg)
    return path


def fast_identifier() -> ForceIdentifier:
    return ForceIdentifier(n_folds=4, n_a0=6, n_bootstrap=8, max_terms=3)


class LabelGuard:
    """Makes every h5py access to a name containing 'labels' raise, and counts the attempts."""

    def __init__(self, mp: pytest.MonkeyPatch) -> None:
        self.hits: list[str] = []
        getitem, get, contains = h5py.Group.__getitem__, h5py.Group.get, h5py.Group.__contains__

        def check(name: object) -> None:
            if isinstance(name, str | bytes) and "labels" in str(name):
                self.hits.append(str(name))
                raise RuntimeError(f"/labels accessed: {name}")

        def guarded_getitem(grp, name):
            check(name)
            return getitem(grp, name)

        def guarded_get(grp, name, *a, **k):
            check(name)
            return get(grp, name, *a, **k)

        def guarded_contains(grp, name):
            check(name)
            return contains(grp, name)

        mp.setattr(h5py.Group, "__getitem__", guarded_getitem)
        mp.setattr(h5py.Group, "get", guarded_get)
        mp.setattr(h5py.Group, "__contains__", guarded_contains)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """identify_trace on a small labelled trace, with every access to /labels made to fail."""
    tmp = tmp_path_factory.mktemp("infer")
    path = small_trace(tmp / "trace.h5")
    with pytest.MonkeyPatch.context() as mp:
        guard = LabelGuard(mp)
        result = identify_trace(path, tmp / "out", identifier=fast_identifier(),
                                figures=identify_figures)
        guard_works = False
        try:
            read_trace(path, labels=True)
        except RuntimeError:
            guard_works = True
    return {"path": path, "out": tmp / "out", "result": result, "guard": guard,
            "guard_works": guard_works}


def test_labels_are_never_read(run):
    # the guard does catch a labels read (so this test can fail) ...
    assert run["guard_works"]
    # ... and identify_trace made none (the one hit is the deliberate read above)
    assert run["guard"].hits == ["labels"]


def test_force_h5_is_aligned_with_the_input(run):
    trace = read_trace(run["path"])
    ide = run["result"]["identifier"]
    cal = calibrate(trace)
    with h5py.File(run["out"] / "force.h5", "r") as f:
        force = f["force_n"][()]
        lo, hi = f["force_lo_n"][()], f["force_hi_n"][()]
        gap = f["gap_m"][()]
        time_s = f["time_s"][()]
        assert f["force_n"].attrs["unit"] == "N" and f["gap_m"].attrs["unit"] == "m"
        assert f.attrs["row"] == -1
    assert force.shape == trace.deflection_m.shape == lo.shape == hi.shape == gap.shape
    # sample by sample: the identifier's dimensionless force times k L_ref
    k_l = trace.spring_constant_n_per_m * trace.gap_m
    np.testing.assert_allclose(force, ide.force_ * k_l, rtol=1e-12, equal_nan=True)
    np.testing.assert_allclose(time_s, np.arange(trace.n_samples) / trace.sample_rate_hz)
    np.testing.assert_allclose(gap, (cal.gap - ide.state_x_) * trace.gap_m, rtol=1e-12)
    # the denoised gap follows the measured deflection to within the noise (0.5 % of 15 nm)
    z_meas = trace.gap_m - trace.deflection_m
    assert np.sqrt(np.mean((gap - z_meas) ** 2)) < 0.02 * 15e-9
    ok = np.isfinite(lo) & np.isfinite(force)
    assert ok.mean() > 0.9
    assert np.all(lo[ok] <= hi[ok])


def test_model_json_reproduces_the_force(run):
    """The saved model, reloaded, gives force_n from the saved gap and the denoised rate."""
    model = IdentifiedModel.load(run["out"] / "model.json")
    ide = run["result"]["identifier"]
    trace = read_trace(run["path"])
    with h5py.File(run["out"] / "force.h5", "r") as f:
        force, gap = f["force_n"][()], f["gap_m"][()]
    f_si = model.force_si(gap, -ide.state_v_ * trace.gap_m * model.scales.omega0)
    np.testing.assert_allclose(f_si, force, rtol=1e-9, atol=1e-6 * np.nanmax(np.abs(force)))
    assert model.equation() == ide.model_.equation()


def test_result_json(run):
    res = json.loads((run["out"] / "result.json").read_text())
    model = IdentifiedModel.load(run["out"] / "model.json")
    assert res["format"] == "afmlearn-identify-result"
    # model.json is the fitted law; "equation" is the law to quote, the same unless the
    # exponent is fixed because the data do not bound it (afmlearn.identify.fixed_exponent)
    assert res["fitted_equation"] == model.equation()
    assert res["fitted_equation_si"] == model.equation_si()
    quoted = (res["exponent_fixed"] or {}).get("equation", model.equation())
    assert res["equation"] == quoted
    assert res["input"] == str(run["path"].resolve())
    assert [c["term"] for c in res["coefficients"]] == model.library.names
    for c, si in zip(res["coefficients"], model.si_terms(), strict=True):
        assert c["coefficient_si"] == pytest.approx(si["coefficient"])
        if "band_si" in c:
            assert c["band_si"][0] <= c["band_si"][1]
    cal = res["calibration"]
    assert cal["spring_constant_n_per_m"] == 20.68
    assert cal["quality_factor"] == 443.0
    assert cal["omega"] == pytest.approx(1.0)
    assert cal["samples_per_period"] == pytest.approx(100.0)
    assert cal["drive_source"] == "free_deflection"
    # physical summary consistent with the force file
    with h5py.File(run["out"] / "force.h5", "r") as f:
        force = f["force_n"][()]
    s = res["summary"]
    assert s["peak_repulsive_force_n"] == pytest.approx(max(np.nanmax(force), 0.0), rel=1e-9)
    assert 0.0 <= s["contact_fraction"] <= 1.0
    assert 0.0 < s["state_accuracy_heldout"] <= 1.0
    # candidates table: one knee and one AICc row, each with the lever terms it kept
    sel = res["selection"]
    table = sel["candidates"]
    assert len(table) == len(run["result"]["identifier"].candidates_) >= 2
    assert [r["knee"] for r in table].count(True) == 1
    assert table[sel["knee_index"]]["knee"] and table[sel["ic_index"]]["ic_choice"]
    for r in table:
        assert len(r["terms"]) == r["n_terms"]
        assert {"x'", "x"} <= set(r["terms"])           # boxed away from zero
    knee_force_terms = [t for t in table[sel["knee_index"]]["terms"] if t not in LINEAR_TERMS]
    assert len(knee_force_terms) == len(model.library.names)  # refined, same support
    assert res["afmlearn_version"] and res["runtime_s"] > 0


def test_figures_are_written(run):
    for name in ("pareto", "coefficients", "orbit", "force"):
        p = run["out"] / f"{name}.png"
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 10_000
    assert not list(run["out"].glob(".*.tmp"))  # atomic writes leave no temporaries


def test_sweep_row_rules(tmp_path, run):
    trace = read_trace(run["path"])
    meta = trace.metadata()
    meta["drive_frequency_hz"] = np.array([meta["drive_frequency_hz"]] * 2)
    sweep = Trace(np.stack([trace.deflection_m] * 2), **meta)
    path = write_trace(sweep, tmp_path / "sweep.h5") or tmp_path / "sweep.h5"
    with pytest.raises(ValueError, match=r"sweep of 2 rows; pass row=<i> with i in \[0, 2\)"):
        identify_trace(path, tmp_path / "o", identifier=fast_identifier(), figures=False)
    with pytest.raises(ValueError, match=r"row must be an integer in \[0, 2\)"):
        identify_trace(path, tmp_path / "o", row=2, identifier=fast_identifier())
    with pytest.raises(ValueError, match="row must be null for a single"):
        identify_trace(run["path"], tmp_path / "o", row=0, identifier=fast_identifier())
    assert not (tmp_path / "o").exists()


def test_jsonable():
    out = jsonable({"a": np.float64(1.5), "b": np.arange(2), "c": (np.nan, np.inf), 3: None})
    assert out == {"a": 1.5, "b": [0, 1], "c": [None, None], "3": None}
    json.dumps(out, allow_nan=False)
