"""afmlearn.simulate and scripts/simulate.py: the real configs, tiny scenarios, tmp outputs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hydra.errors import MissingConfigException
from omegaconf import OmegaConf

from afmlearn.io import MANIFEST, Experiment, TraceReader, iter_traces, read_trace
from afmlearn.simulate import REGIME_CODES, build, si_labels, simulate
from simulator import SteadyState
from simulator.forces import DMT, ForceSum, HystereticJKR, ViscoelasticDMT

ROOT = Path(__file__).resolve().parents[2]
CONF = ROOT / "conf"
FORCES = sorted(p.stem for p in (CONF / "force").glob("*.yaml"))
SCENARIOS = sorted(p.stem for p in (CONF / "scenario").glob("*.yaml"))
CANTILEVERS = sorted(p.stem for p in (CONF / "cantilever").glob("*.yaml"))
SENSORS = sorted(p.stem for p in (CONF / "sensor").glob("*.yaml"))

#: forces without a repulsive wall, or with a stiff z^-8 wall, need their own set-up
FORCE_SETUP = {
    "lj": ["cantilever=soft_lj", "excitation.free_amplitude_ratio=0.1"],
    "vdw_sphere": ["excitation.free_amplitude_ratio=0.5"],
}
CONTACT_FORCES = {"dmt", "dmt_cone", "dmt_visco", "dmt_expdamp", "jkr", "jkr_hysteretic",
                  "electrostatic"}
DISSIPATIVE = {"dmt_visco", "dmt_expdamp", "jkr_hysteretic"}


def test_config_groups_are_complete():
    assert set(FORCES) == {"lj", "dmt", "dmt_visco", "dmt_expdamp", "jkr", "jkr_hysteretic",
                           "electrostatic", "none", "dmt_cone", "vdw_sphere"}
    assert set(SCENARIOS) == {"steady", "transient", "approach", "sweep", "spectroscopy",
                              "lockin"}
    assert {"tapping", "nclr", "nclr_3mode", "soft_lj", "sweet_spot"} <= set(CANTILEVERS)
    assert set(SENSORS) == {"default", "realistic", "nonlinear_detector"}


@pytest.mark.parametrize("force", FORCES)
def test_every_force_gives_a_sane_tapping_trace(force, run_sim):
    """Default cantilever and settling, 20 recorded periods: finite, physical, labelled."""
    metrics, obj = run_sim(f"force={force}", "scenario.n_periods=20",
                       *FORCE_SETUP.get(force, []))
    trace = read_trace(metrics["output"], labels=True)
    assert np.all(np.isfinite(trace.deflection_m))
    assert trace.labels.model["name"] == obj["force"].name
    if force in CONTACT_FORCES:
        assert metrics["regime"] == "repulsive"
        assert 0.0 < metrics["contact_fraction"] < 0.4
        assert metrics["set_point"] < 0.9  # amplitude reduced vs free
        assert 0.5e-9 < metrics["peak_force_n"] < 50e-9
    if force == "none":
        assert metrics["set_point"] == pytest.approx(1.0, abs=1e-3)
    if force in DISSIPATIVE:
        assert metrics["dissipated_energy_ev"] > 1.0
    elif force != "lj":
        assert abs(metrics["dissipated_energy_ev"]) < 0.1


#: a tiny set-point series (tests/afmlearn/conftest.py's TINY has the other scenarios)
TINY_SPECTROSCOPY = ["scenario.n_periods=5", "scenario.settle_periods=10",
                     "scenario.gap_ratios=[0.9,0.7,0.5]"]


#: scenarios that write a deflection record (lockin writes lock-in curves: test below)
DEFLECTION_SCENARIOS = [s for s in SCENARIOS if s != "lockin"]


def test_lockin_scenario_writes_valid_curves(run_sim):
    """Lock-in curves: amplitude/phase vs piezo, approach then retraction, no deflection."""
    metrics, _ = run_sim("scenario=lockin", "scenario.n_periods=300",
                         "excitation.free_amplitude_ratio=1.5")
    trace = read_trace(metrics["output"])
    assert trace.is_curves and trace.deflection_m is None
    n = trace.amplitude_m.shape[0]
    assert trace.phase_rad.shape == trace.z_piezo_m.shape == trace.segment.shape == (n,)
    seg = np.asarray(trace.segment)
    assert set(np.unique(seg)) == {0, 1} and np.all(np.diff(seg) >= 0)  # approach, then back
    z = np.asarray(trace.z_piezo_m)
    assert np.all(np.diff(z[seg == 0]) <= 0) and np.all(np.diff(z[seg == 1]) >= 0)
    # far from the sample, at the start of the approach, the lever oscillates freely: free
    # amplitude, phase ~ pi/2 at f0 (the retraction's far end still rings back: time constant
    # 2Q periods, longer than this short ramp)
    far = (seg == 0) & (z >= np.quantile(z[seg == 0], 0.8))
    a_far = float(np.median(trace.amplitude_m[far]))
    assert a_far == pytest.approx(1.5 * 10e-9, rel=0.05)
    assert float(np.median(trace.phase_rad[far])) == pytest.approx(np.pi / 2, abs=0.05)
    # the tip meets the sample at the closest approach: the amplitude drops
    assert float(trace.amplitude_m[np.argmin(z)]) < 0.9 * a_far


@pytest.mark.parametrize("scenario", DEFLECTION_SCENARIOS)
def test_every_scenario_writes_a_valid_file(scenario, run_sim, tiny):
    tiny = {"spectroscopy": TINY_SPECTROSCOPY, **tiny}
    metrics, obj = run_sim(f"scenario={scenario}", *tiny[scenario])
    path = Path(metrics["output"])
    trace = read_trace(path)
    assert trace.labels is None  # labels only when asked for
    labelled = read_trace(path, labels=True)
    lab = labelled.labels
    assert lab.force_n.shape == trace.deflection_m.shape
    assert lab.modal_m.shape == (1, *trace.deflection_m.shape)
    assert lab.effect == "none"
    assert trace.excitation == "tip"
    assert trace.spring_constant_n_per_m == 20.68
    assert trace.resonance_frequency_hz == 259.9e3
    assert trace.tip_radius_m == 10e-9
    assert trace.free_amplitude_m == pytest.approx(15e-9)
    assert trace.free_deflection_m is not None and trace.free_deflection_m.size > 0
    assert trace.description and scenario in trace.description
    model = lab.model
    for key in ("force", "cantilever", "excitation", "scenario", "sensor", "seed",
                "calibration"):
        assert key in model
    assert model["force"]["model"] == "dmt"
    assert model["calibration"]["length_m"] == 10e-9
    if scenario == "sweep":
        sweep = obj["scenario"]
        assert trace.is_sweep and trace.n_points == 6
        np.testing.assert_allclose(trace.drive_frequency_hz, sweep.row_omegas() * 259.9e3)
        assert trace.sample_rate_hz == pytest.approx(259.9e3 * sweep.samples_per_period)
        for name in ("amplitude_m", "contact_fraction", "dissipated_energy_j",
                     "coupling_strength", "regime_code", "phase_rad"):
            assert lab.scalars[name].shape == (6,)
        assert set(np.unique(lab.scalars["regime_code"])) <= set(REGIME_CODES.values())
        assert obj["result"] is None  # streamed, never held whole
        assert np.shape(trace.drive_phase_rad) == (6,)
    elif scenario == "spectroscopy":
        assert trace.is_series and not trace.is_sweep and trace.n_points == 3
        np.testing.assert_allclose(trace.gap_m, np.array([0.9, 0.7, 0.5]) * 15e-9)
        assert trace.drive_frequency_hz == pytest.approx(259.9e3)
        np.testing.assert_allclose(trace.drive_phase_rad, obj["result"].drive_phase)
        for name in ("amplitude_m", "dissipated_energy_j", "drive_energy_j",
                     "damping_energy_j", "regime_code", "peak_force_n"):
            assert lab.scalars[name].shape == (3,)
        assert lab.extra["tip_sample_gap_m"].shape == trace.deflection_m.shape
    else:
        assert not trace.is_sweep
        assert np.ndim(trace.drive_frequency_hz) == 0
        assert lab.scalars["regime"] in REGIME_CODES
        assert lab.extra["tip_sample_gap_m"].shape == trace.deflection_m.shape
        assert trace.drive_phase_rad == pytest.approx(obj["result"].drive_phase)
    if scenario == "approach":  # the rest gap varies: a dataset
        assert np.shape(trace.gap_m) == trace.deflection_m.shape
        assert trace.gap_m[0] == pytest.approx(20e-9, rel=1e-3)
        half = trace.n_samples // 2  # approach, then retraction (approach.yaml: retract)
        np.testing.assert_array_equal(trace.segment, np.repeat(np.int8([0, 1]), half))
        assert np.all(np.diff(trace.gap_m[:half]) < 0) and np.all(np.diff(trace.gap_m[half:]) > 0)
    elif scenario == "transient":  # the step in topography: a dataset too
        k = int(lab.scalars["step_index"])
        assert 0 < k < trace.n_samples
        assert lab.scalars["step_m"] == pytest.approx(-2e-9)
        np.testing.assert_allclose(trace.gap_m[[0, k - 1, k, -1]], [10e-9, 10e-9, 8e-9, 8e-9])
    elif scenario != "spectroscopy":
        assert trace.gap_m == pytest.approx(10e-9)


def test_sweep_rows_match_the_in_memory_sweep(run_sim, tiny):
    """Streaming rows through TraceWriter gives the same labels as Sweep.run()."""
    metrics, obj = run_sim("scenario=sweep", *tiny["sweep"], "noise.level=0")
    trace = read_trace(metrics["output"], labels=True)
    result = obj["scenario"].run(obj["system"])
    si = result.to_si(obj["scales"])
    np.testing.assert_allclose(trace.labels.force_n, si["force_n"])
    np.testing.assert_allclose(trace.deflection_m, si["deflection_m"])
    np.testing.assert_allclose(trace.labels.scalars["amplitude_m"], si["labels"]["amplitude_m"])
    with TraceReader(metrics["output"]) as reader:
        assert reader.row(4).drive_frequency_hz == pytest.approx(trace.drive_frequency_hz[4])


def test_si_label_names_match_simulation_result_to_si(tmp_path, compose_cfg):
    cfg = compose_cfg([f"output={tmp_path / 'x.h5'}"])
    obj = build(cfg)
    r = SteadyState(n_periods=2, settle_periods=0).run(obj["system"])
    ours = si_labels(r.labels, obj["scales"])
    theirs = r.to_si(obj["scales"])["labels"]
    assert set(ours) == set(theirs)
    for key, value in theirs.items():
        if isinstance(value, str):
            assert ours[key] == value
        else:
            assert ours[key] == pytest.approx(float(value))


def test_metrics_and_objects(run_sim, tiny):
    metrics, obj = run_sim(*tiny["steady"])
    for key in ("amplitude_m", "free_amplitude_m", "set_point", "contact_fraction",
                "dissipated_energy_j", "dissipated_energy_ev", "peak_force_n",
                "coupling_strength", "regime", "runtime_s", "output", "model", "scenario"):
        assert key in metrics
    assert metrics["runtime_s"] > 0
    assert isinstance(obj["force"], DMT)
    assert obj["result"].deflection.shape == (1000,)
    assert obj["path"] == Path(metrics["output"])


def test_simulate_leaves_its_config_unchanged(tmp_path, compose_cfg, tiny):
    cfg = compose_cfg([*tiny["steady"], f"output={tmp_path / 'ds'}", "shard.count=2",
                       "shard.index=1", "seed=5", "+dataset.ranges.free_amplitude_ratio=[1,2]"])
    before = OmegaConf.to_yaml(cfg)
    _, obj = simulate(cfg)
    assert OmegaConf.to_yaml(cfg) == before
    assert obj["cfg"].seed == 6 and obj["cfg"].excitation.free_amplitude_ratio != 1.5


def test_labels_false_and_no_free_trace(run_sim, tiny):
    metrics, _ = run_sim(*tiny["steady"], "labels=false", "free_trace=false")
    trace = read_trace(metrics["output"], labels=True)
    assert trace.labels is None
    assert trace.free_deflection_m is None


def test_free_trace_has_the_drive_and_sampling_of_the_trace(run_sim, tiny):
    metrics, obj = run_sim(*tiny["steady"], "noise.level=0")
    trace = read_trace(metrics["output"])
    free = trace.free_deflection_m
    assert free.size == 3 * 200  # free_trace_periods x samples per period
    assert np.ptp(free) / 2 == pytest.approx(trace.free_amplitude_m, rel=1e-3)


def test_noise_is_seeded(run_sim, tiny):
    a, _ = run_sim(*tiny["steady"], "seed=3", name="a.h5")
    b, _ = run_sim(*tiny["steady"], "seed=3", name="b.h5")
    c, _ = run_sim(*tiny["steady"], "seed=4", name="c.h5")
    xa, xb, xc = (read_trace(m["output"]).deflection_m for m in (a, b, c))
    np.testing.assert_array_equal(xa, xb)
    assert not np.array_equal(xa, xc)
    noise = xa - read_trace(a["output"], labels=True).labels.modal_m.sum(axis=0)
    assert np.std(noise) == pytest.approx(0.01 * 15e-9, rel=0.15)


def test_base_excitation_and_higher_modes(run_sim, tiny):
    metrics, obj = run_sim("cantilever=nclr", "excitation=base", *tiny["steady"])
    trace = read_trace(metrics["output"], labels=True)
    assert trace.excitation == "base"
    assert trace.dither_amplitude_m == pytest.approx(obj["excitation"].amplitude * 100e-9)
    np.testing.assert_allclose(trace.higher_mode_frequencies_hz, [6.267 * 164.52e3])
    assert trace.labels.modal_m.shape == (2, trace.n_samples)


@pytest.mark.parametrize("cantilever", CANTILEVERS)
def test_every_cantilever_builds(tmp_path, cantilever, compose_cfg):
    cfg = compose_cfg([f"cantilever={cantilever}", f"output={tmp_path / 'x.h5'}"])
    obj = build(cfg)
    assert obj["cantilever"].n_modes == cfg.cantilever.n_modes
    assert obj["scales"].length == cfg.cantilever.gap_m


@pytest.mark.parametrize("sensor", SENSORS)
def test_every_sensor_runs(sensor, run_sim, tiny):
    metrics, obj = run_sim(f"sensor={sensor}", *tiny["steady"])
    assert np.all(np.isfinite(read_trace(metrics["output"]).deflection_m))
    assert obj["sensor"].seed == 0


def test_sweet_spot_experiment(tmp_path, compose_cfg):
    cfg = compose_cfg(["experiment=sweet_spot", f"output={tmp_path / 'ss.h5'}",
                            "scenario.n_points=3", "scenario.samples_per_point=200",
                            "scenario.settle_periods=2"])
    assert cfg.scenario.omega_start == 0.990149 and cfg.scenario.omega_stop == 1.1327
    metrics, obj = simulate(cfg)
    cl = obj["cantilever"]
    np.testing.assert_allclose(cl.stiffness, [1.0, 36.0])
    np.testing.assert_allclose(cl.force_gain, [1.0, 13.5 / 10.5])
    np.testing.assert_allclose(cl.contact_damping, [5.7e-3, 8e-3])
    assert obj["force"] == DMT(a0=0.2, vdw=6e-4, stiffness=10.5)  # C1 of docs/sweet_spot.md
    trace = read_trace(metrics["output"])
    assert trace.excitation == "base"
    assert trace.dither_amplitude_m == pytest.approx(2.649109e-3 * 100e-9)
    assert trace.n_points == 6


def test_thesis_sweep_composes(compose_cfg):
    cfg = compose_cfg(["experiment=thesis_sweep"])
    obj = build(cfg)
    sweep = obj["scenario"]
    assert (sweep.n_points, sweep.samples_per_point, sweep.n_rows) == (501, 50_000, 1002)
    assert obj["cantilever"].n_modes == 2
    assert cfg.cantilever.resonance_frequency_hz * sweep.samples_per_period == pytest.approx(
        250e6, rel=1e-5)


def test_force_config_objects(compose_cfg):
    def force(name):
        return build(compose_cfg([f"force={name}", *FORCE_SETUP.get(name, [])]))["force"]

    assert isinstance(force("dmt_visco"), ViscoelasticDMT)
    assert isinstance(force("jkr_hysteretic"), HystereticJKR)
    assert [t.name for t in force("electrostatic").terms] == ["dmt", "electrostatic"]
    assert [t.name for t in force("dmt_expdamp").terms] == ["dmt", "expdamp"]
    assert isinstance(force("dmt_expdamp"), ForceSum)
    assert force("dmt_cone").exponent == 2.0
    dmt = force("dmt")
    assert dmt.a0 == pytest.approx(0.03)  # 0.3 nm / 10 nm


def test_shards_write_a_manifest(tmp_path, run_sim, tiny):
    folder = tmp_path / "ds"
    drawn = []
    for i in range(3):
        metrics, obj = run_sim(*tiny["steady"], f"output={folder}", "shard.count=3",
                           f"shard.index={i}", "seed=5",
                           "+dataset.ranges.free_amplitude_ratio=[1.2,1.8]")
        assert Path(metrics["output"]).name == f"shard-{i:05d}.h5"
        assert obj["cfg"].seed == 5 + i
        assert obj["sensor"].seed == 5 + i
        value = obj["drawn"]["excitation.free_amplitude_ratio"]
        assert 1.2 <= value <= 1.8
        assert metrics["free_amplitude_m"] == pytest.approx(value * 10e-9)
        drawn.append(value)
    assert len(set(drawn)) == 3
    manifest = json.loads((folder / MANIFEST).read_text())
    assert manifest["n_files"] == 3
    traces = list(iter_traces(folder, labels=True))
    assert [t.labels.model["seed"] for t in traces] == [5, 6, 7]
    # the same (seed, index) draws the same parameters
    _, again = run_sim(*tiny["steady"], f"output={tmp_path / 'again'}", "shard.count=3",
                   "shard.index=1", "seed=5", "+dataset.ranges.free_amplitude_ratio=[1.2,1.8]")
    assert again["drawn"]["excitation.free_amplitude_ratio"] == drawn[1]


def test_rerun_skips_finished_shards(tmp_path, run_sim, tiny):
    """An interrupted dataset is resumed: existing (atomically written) shards are kept."""
    folder = tmp_path / "ds"
    args = (*tiny["steady"], f"output={folder}", "shard.count=2", "shard.index=0")
    first, _ = run_sim(*args)
    mtime = Path(first["output"]).stat().st_mtime_ns
    again, _ = run_sim(*args)
    assert again["skipped"] is True
    assert Path(again["output"]).stat().st_mtime_ns == mtime
    redo, _ = run_sim(*args, "shard.overwrite=true")
    assert "skipped" not in redo
    assert Path(redo["output"]).stat().st_mtime_ns != mtime


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        (["noise.level=-0.1"], "noise.level"),
        (["noise.level=2"], "noise.level"),
        (["scenario.omega=-1"], "scenario: omega"),
        (["+force.bogus=1"], "force:"),
        (["excitation.free_amplitude_ratio=0"], "excitation.free_amplitude_ratio"),
        (["excitation.amplitude=-1"], "excitation.amplitude"),
        (["shard.count=2", "shard.index=2", "output=ds"], "shard.index"),
        (["shard.count=2", "output=ds.h5"], "output"),
        (["output=trace.txt"], "output"),
        (["seed=-1"], "seed"),
        (["force=vdw_sphere"], "free_amplitude_ratio"),
        (["+dataset.ranges.nonexistent_key=[0,1]"], "dataset.ranges"),
        (["+dataset.ranges.free_amplitude_ratio=[2,1]"], "dataset.ranges"),
        (["cantilever=sweet_spot", "cantilever.n_modes=3"], "cantilever.n_modes"),
    ],
)
def test_bad_overrides_raise_value_errors(tmp_path, overrides, match, tiny, compose_cfg):
    overrides = [o if not o.startswith("output=") else f"output={tmp_path / o[7:]}"
                 for o in overrides]
    if not any(o.startswith("output=") for o in overrides):
        overrides.append(f"output={tmp_path / 'x.h5'}")
    cfg = compose_cfg([*tiny["steady"], *overrides])
    with pytest.raises(ValueError, match=match):
        simulate(cfg)


def test_unknown_force_names_the_options(compose_cfg):
    with pytest.raises(MissingConfigException, match="dmt_visco"):
        compose_cfg(["force=no_such_force"])


def test_script_runs_end_to_end(tmp_path, tiny):
    out = tmp_path / "x.h5"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    proc = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "simulate.py"), "force=jkr_hysteretic",
         "cantilever=nclr", "scenario=sweep", *tiny["sweep"], "noise.level=0.01", "seed=0",
         f"output={out}", f"hydra.run.dir={tmp_path / 'run'}", "progress=false"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "amplitude_m" in proc.stdout
    trace = read_trace(out, labels=True)
    assert trace.is_sweep and trace.labels.model["name"] == "jkr_hysteretic"
    assert (tmp_path / "run" / ".hydra" / "config.yaml").exists()


def test_script_rejects_bad_input(tmp_path):
    proc = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "simulate.py"), "noise.level=-1",
         f"output={tmp_path / 'x.h5'}", f"hydra.run.dir={tmp_path / 'run'}"],
        cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True,
        text=True, timeout=600)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "error: noise.level must be a number in [0, 1], got -1"]


# ---------------------------------------------------------------------------- spectroscopy
def test_spectroscopy_gaps_in_metres_or_reference_units(run_sim):
    """scenario.gaps_m [m], scenario.gaps [L_ref] and gap_ratios give the same rows."""
    common = ["scenario=spectroscopy", "scenario.n_periods=3", "scenario.settle_periods=5",
              "noise.level=0"]
    a, _ = run_sim(*common, "scenario.gaps_m=[12e-9,8e-9]", name="a.h5")
    b, _ = run_sim(*common, "scenario.gaps=[1.2,0.8]", name="b.h5")
    c, _ = run_sim(*common, "scenario.gap_ratios=[0.8,0.5333333333333333]", name="c.h5")
    ta, tb, tc = (read_trace(m["output"]) for m in (a, b, c))
    np.testing.assert_allclose(ta.gap_m, [12e-9, 8e-9])
    np.testing.assert_allclose(tb.gap_m, ta.gap_m)
    np.testing.assert_allclose(tc.gap_m, ta.gap_m, rtol=1e-12)
    np.testing.assert_allclose(tb.deflection_m, ta.deflection_m, rtol=0, atol=1e-20)
    np.testing.assert_allclose(tc.deflection_m, ta.deflection_m, rtol=1e-9, atol=1e-18)


def test_spectroscopy_reads_as_an_experiment(run_sim):
    """The file is a series: one observation per rest gap, with per-row labels."""
    metrics, obj = run_sim("scenario=spectroscopy", "scenario.n_periods=5",
                           "scenario.settle_periods=20", "scenario.gaps=[1.3,1.0,0.7]",
                           "scenario.drive_phases=[0.3,-2.0,1.5]", "noise.level=0")
    exp = Experiment.read(metrics["output"], labels=True)
    assert exp.kind == "series" and len(exp) == 3
    np.testing.assert_allclose(exp.gaps_m, [13e-9, 10e-9, 7e-9])
    np.testing.assert_allclose(exp.drive_phases_rad, [0.3, -2.0, 1.5], atol=1e-9)
    amplitudes = [obs.labels.scalars["amplitude_m"] for obs in exp]
    assert amplitudes[0] > amplitudes[1] > amplitudes[2]  # tapping: the surface limits it
    assert metrics["amplitude_m"] == pytest.approx(max(amplitudes))
    for obs in exp:  # each row's labels belong to that row (no noise: equal sums)
        np.testing.assert_allclose(obs.deflection_m, obs.labels.modal_m.sum(axis=0),
                                   rtol=1e-12, atol=1e-22)


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        (["scenario.gaps_m=[1e-8,-1e-9]"], "scenario.gaps_m"),
        (["scenario.gaps_m=[1e-8]", "scenario.gaps=[1.0]"], "scenario.gaps_m and"),
        (["scenario.gaps=[1.0,0]"], "scenario: gaps"),
        (["scenario.drive_phases=[0.0]"], "scenario: drive_phases"),
        (["force=vdw_sphere", "scenario.gaps=[0.4]"], "free_amplitude_ratio"),
    ],
)
def test_bad_spectroscopy_settings(tmp_path, compose_cfg, overrides, match):
    cfg = compose_cfg(["scenario=spectroscopy", *TINY_SPECTROSCOPY,
                       f"output={tmp_path / 'x.h5'}", *overrides])
    with pytest.raises(ValueError, match=match):
        simulate(cfg)
