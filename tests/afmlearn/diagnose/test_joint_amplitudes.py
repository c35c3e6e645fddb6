"""Several free amplitudes end to end: a cone that one free amplitude leaves unbounded is
found, with a bounded exponent, when the same draw is recorded at two free amplitudes."""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.diagnose import Diagnoser
from afmlearn.diagnose.hypotheses import ContactGeometry
from afmlearn.diagnose.observation import read_experiment
from afmlearn.diagnose.synthetic import hidden_series, series_files, simulate_series

SETTING = {"samples_per_period": 100, "n_periods": 20.0, "noise_level": 0.01}


@pytest.fixture(scope="module")
def cone(tmp_path_factory):
    """A cone draw (exponent drawn in 1.9 - 2.4) as 2 x 4 set-points at two free amplitudes,
    and its one-amplitude twin (the same 8 set-points, all at the first amplitude)."""
    folder = tmp_path_factory.mktemp("amplitudes")
    case = hidden_series(np.random.default_rng([0, 79]), folder / "two",
                         causes="contact_geometry", n_points=8, free_amplitudes=2, **SETTING)
    one = simulate_series(case.one_amplitude(), folder / "one.h5", **SETTING)
    return case, series_files(folder / "two"), one


def _diagnose(files) -> Diagnoser:
    # the code under test gets the files only (labels never read); one cause keeps it fast
    return Diagnoser(hypotheses=[ContactGeometry()], max_causes=1, max_folds=4).fit(
        read_experiment(files))


def test_a_second_free_amplitude_bounds_the_cone(cone):
    case, files, one = cone
    truth = case.effects["contact_geometry"]["exponent"]
    two = _diagnose(files)
    single = _diagnose([one])
    d2 = two.candidates_[0].delta_chi2
    d1 = single.candidates_[0].delta_chi2
    # two amplitudes: named, with an interval that is bounded and holds the truth
    assert two.cause_ == "contact_geometry" and two.gain_ > 0.2
    lo, hi = two.exponent_interval_
    assert two.exponent_bounded_ and lo <= truth <= hi and hi - lo < 1.0
    # one amplitude, same tip and law: far less evidence and no bounded exponent
    assert d2 > 5 * max(d1, 1.0)
    assert not single.exponent_bounded_
