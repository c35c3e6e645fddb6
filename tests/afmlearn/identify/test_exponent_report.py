"""The identifier's outputs never quote an unbounded contact exponent as the law (issue 14
audit: ``F_ts = 1093 delta^3.49996`` with an interval of 0.50-4.00).

The single-orbit refit itself runs in tests/scripts/test_identify_cli.py (its fixture's
30-period orbit does not bound the exponent); here the decisions on constructed summaries and
(slow) the joint output-error path on the audit's short series."""

from __future__ import annotations

import re
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from afmlearn.identify.fixed_exponent import SPHERE_EXPONENT, fixed_exponent_law
from afmlearn.identify.infer import identify_trace
from afmlearn.identify.joint_outputs import format_exponent
from afmlearn.simulate import simulate

ROOT = Path(__file__).resolve().parents[3]


def _fitted(p: float, interval: tuple[float, float], bounded: bool) -> SimpleNamespace:
    """A stand-in for a fitted identifier: only what the decision reads before any refit."""
    return SimpleNamespace(summary_={"interaction_exponent": p,
                                     "interaction_exponent_interval": interval,
                                     "interaction_exponent_bounded": bounded},
                           orbit_=None, joint_=None)


def test_a_bounded_exponent_is_quoted_as_fitted():
    assert fixed_exponent_law(_fitted(1.48, (1.3, 1.7), True)) is None


def test_unbounded_interval_excluding_the_sphere_fixes_nothing_and_says_which_end_holds():
    law = fixed_exponent_law(_fitted(3.84114, (2.5, 4.0), False))
    assert law is not None and law.exponent is None and law.model is None
    assert law.text.startswith("interaction exponent at least 2.50")
    assert "delta^3.84114" in law.text and "not an identified exponent" in law.text


def test_the_terminal_line_is_the_fixed_exponent_note_with_the_interval():
    note = ("interaction exponent 1.5 FIXED (sphere, Hertz/DMT): not identifiable from these "
            "data (95 % profile interval 0.50-4.00 reaches the end of the profiled range)")
    line = format_exponent({"interaction_exponent": 3.49996,
                            "interaction_exponent_interval": [0.5, 4.0],
                            "interaction_exponent_bounded": False,
                            "interaction_exponent_fixed": SPHERE_EXPONENT,
                            "interaction_exponent_note": note})
    assert line.startswith(note) and "3.50" not in line
    # without a note (a bounded exponent) the exponent and its interval, as before
    assert format_exponent({"interaction_exponent": 1.48,
                            "interaction_exponent_interval": [1.3, 1.7],
                            "interaction_exponent_bounded": True}) == \
        "interaction exponent 1.48 (95 % profile interval 1.30-1.70)"


@pytest.mark.slow
def test_short_series_of_one_amplitude_quotes_the_output_error_fit_at_the_sphere(tmp_path):
    """The audit's series (plain DMT, 3 set-points x 20 periods, one free amplitude: its
    exponent profile is flat, 0.50-4.00, and the fit printed ``delta^3.84114``): the quoted
    law is the output-error profile's own fit at p = 1.5, inside the 95 % interval, and its
    van der Waals coefficient is the simulated sphere's ``H R / 6`` (measured 4.5 % off; the
    contact coefficient is not tested: a0 and the stiffness still trade on such data)."""
    path = tmp_path / "spectro.h5"
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        cfg = compose("simulate", overrides=[
            "scenario=spectroscopy", "scenario.gaps=[0.9,0.7,0.5]", "scenario.n_periods=20",
            "progress=false", f"output={path}"])
    simulate(cfg)
    res = identify_trace(path, tmp_path / "out")
    summary, fixed = res["summary"], res["exponent_fixed"]
    assert summary["interaction_exponent_bounded"] is False  # one amplitude, 3 x 20 periods
    assert fixed["exponent"] == SPHERE_EXPONENT
    assert fixed["method"] == "the output-error profile's fit at this exponent"
    assert res["equation"] == fixed["equation"] != res["fitted_equation"]
    assert re.search(r"delta\^1\.5(?![0-9])", res["equation_si"])
    assert -1.0 < fixed["profile_rise"] < 3.841
    vdw = [t for t in fixed["si_terms"] if t["term"].startswith("z^-2")]
    hr6 = cfg.force.hamaker_j * cfg.cantilever.tip_radius_m / 6.0
    assert len(vdw) == 1 and abs(vdw[0]["coefficient"]) == pytest.approx(hr6, rel=0.2)
    # force.h5 holds the quoted law's force with its band (conditional on p = 1.5), the fitted
    # law's force beside it
    with h5py.File(tmp_path / "out" / "force.h5", "r") as f:
        assert f.attrs["equation"] == res["equation"] and float(f.attrs["exponent_fixed"]) == 1.5
        force, lo, hi = (f[k][()] for k in ("force_n", "force_lo_n", "force_hi_n"))
        assert f["fitted_force_n"].shape == force.shape
        assert not np.allclose(f["fitted_force_n"][()], force, rtol=1e-3, atol=0.0)
    assert np.all(np.isfinite(lo)) and np.all((lo <= force + 1e-18) & (force <= hi + 1e-18))
    assert np.max(hi - lo) > 0
