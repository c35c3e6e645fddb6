"""The hidden-effect generator at two free amplitudes: the design, one file per amplitude
(valid trace files, truth only in /labels), the one-amplitude twin of the same draw."""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.diagnose.observation import build_observations, drive_groups, read_experiment
from afmlearn.diagnose.synthetic import (
    SeriesCase,
    _simulate_groups,
    draw_series_case,
    effect_visibility,
    series_files,
    simulate_series,
)
from afmlearn.io import Experiment, read_trace

OPTS = {"samples_per_period": 60, "n_periods": 6, "noise_level": 0.01, "free_periods": 2}


def test_two_amplitude_draw_design():
    cases = [draw_series_case(np.random.default_rng([4, i]), free_amplitudes=2)
             for i in range(40)]
    assert cases == [draw_series_case(np.random.default_rng([4, i]), free_amplitudes=2)
                     for i in range(40)]
    for c in cases:
        amps = c.row_amplitudes_m
        assert len(c.amplitudes_m) == 2 and amps.size == 8
        a1, a2 = c.amplitudes_m
        assert a1 == c.free_amplitude_m and 2.5 <= a2 / a1 <= 3.3
        assert 12e-9 <= a1 and a2 <= 40e-9 * (1 + 1e-12)          # both in the tapping range
        assert np.array_equal(amps, [a1] * 4 + [a2] * 4)
        sp = np.asarray(c.setpoints)
        for half in (sp[:4], sp[4:]):                 # each amplitude spans the range
            assert np.all(np.diff(half) < 0) and half[0] > 0.7 and half[-1] < 0.55
        # dealt alternately from one 8-point approach
        merged = np.empty(8)
        merged[0::2], merged[1::2] = sp[:4], sp[4:]
        assert np.all(np.diff(merged) < 0)
        assert np.allclose(c.gaps_m, sp * amps, rtol=0, atol=0)
        assert SeriesCase.from_dict(c.to_dict()) == c
        twin = c.one_amplitude()
        assert np.all(twin.row_amplitudes_m == a1) and twin.setpoints == c.setpoints
        assert "free_amplitudes_m" not in twin.to_dict()
    # one amplitude: the case (and its label dict) has no per-row amplitudes
    one = draw_series_case(np.random.default_rng(9))
    assert one.free_amplitudes_m == () and "free_amplitudes_m" not in one.to_dict()
    assert one == draw_series_case(np.random.default_rng(9), free_amplitudes=1)
    for bad in ({"free_amplitudes": 3}, {"free_amplitudes": True},
                {"free_amplitudes": 2, "n_points": 7}):
        with pytest.raises(ValueError, match="free_amplitudes|n_points"):
            draw_series_case(np.random.default_rng(0), **bad)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    case = draw_series_case(np.random.default_rng(3), causes="contact_geometry", n_points=4,
                            free_amplitudes=2)
    folder = simulate_series(case, tmp_path_factory.mktemp("amp") / "experiment", **OPTS)
    return case, folder


def test_one_file_per_free_amplitude_truth_only_in_labels(written):
    case, folder = written
    files = series_files(folder)
    assert [f.name for f in files] == ["amplitude-0.h5", "amplitude-1.h5"]
    for f, amp, rows in zip(files, case.amplitudes_m, ([0, 1], [2, 3]), strict=True):
        tr = read_trace(f)                                 # valid trace format v1
        assert tr.labels is None and tr.n_points == 2
        assert tr.free_amplitude_m == amp
        assert np.allclose(tr.gap_m, case.gaps_m[rows], rtol=1e-15)
        assert "contact" not in (tr.description or "") and "cone" not in f.name
        lab = read_trace(f, labels=True).labels
        assert lab.effect == "contact_geometry"
        assert SeriesCase.from_dict(lab.model["case"]) == case
    # one experiment of the two files; the diagnosis sees two drive groups whose F_c
    # ratio is the free amplitudes' (same lever, same drive frequency)
    exp = read_experiment(files)
    assert isinstance(exp, Experiment) and len(exp) == 4
    obs = build_observations(list(exp), phase_sd=0.02, window_periods=5.0, max_windows=2,
                             warnings=[])
    groups, drives = drive_groups(obs)
    assert groups == [0, 0, 1, 1]
    a1, a2 = case.amplitudes_m
    assert abs(drives[1] / drives[0] - a2 / a1) < 0.02     # from the noisy free traces
    # one file alone: one group, the old single drive
    g1, d1 = drive_groups(obs[:2])
    assert g1 == [0, 0] and d1 == [drives[0]]


def test_one_amplitude_twin_shares_the_first_amplitudes_records():
    case = draw_series_case(np.random.default_rng(3), causes="electrostatic", n_points=4,
                            free_amplitudes=2)
    two = _simulate_groups(case, min_tapping=0, **OPTS)
    one = _simulate_groups(case.one_amplitude(), min_tapping=0, **OPTS)
    assert [g.rows for g in two] == [(0, 1), (2, 3)] and [g.rows for g in one] == [(0, 1, 2, 3)]
    assert np.array_equal(two[0].deflection_m, one[0].deflection_m[:2])
    assert np.array_equal(two[0].free_deflection_m, one[0].free_deflection_m)
    # the second amplitude's rows swing far wider than the twin's at the same set-points,
    # and no row beyond its own free amplitude (+ noise)
    ptp2 = np.ptp(two[1].deflection_m, axis=1) / np.ptp(one[0].deflection_m[2:], axis=1)
    assert np.all(ptp2 > 2.0)
    for data in (*two, *one):
        assert np.max(np.abs(data.deflection_m)) < 1.1 * data.free_amplitude_m
    # the oracle covers every row (each in its own free amplitude's noise units)
    vis = effect_visibility(case, samples_per_period=60, n_periods=6, n_harmonics=20)
    assert len(vis["electrostatic"]["chi2_rows"]) == 4
    assert all(v > 0 for v in vis["electrostatic"]["chi2_rows"])
