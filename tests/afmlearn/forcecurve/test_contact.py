"""Static force curves: known contact laws recovered, the free exponent's gain measured on the
retraction, adhesion hysteresis from the loop; and the real curves run end to end."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from afmlearn.forcecurve import ContactFit, analyse_curve, branch
from afmlearn.io.instruments import ForceCurve, open_recording

ROOT = Path(__file__).resolve().parents[3]
FORCE = ROOT / "tests" / "data" / "afmformats_forcecurves"
K = 0.5  # N/m


def synthetic(exponent: float, *, pull_off: float = 0.0, seed: int = 0) -> ForceCurve:
    """A curve of a law ``a delta^p - F_ad`` (contact at d = 0), approach then retraction;
    the retraction's adhesion is ``F_ad + pull_off`` (a neck: hysteresis)."""
    rng = np.random.default_rng(seed)
    d = np.linspace(100e-9, -20e-9, 600)
    a = 2e-9 / (20e-9) ** exponent  # 2 nN at 20 nm indentation
    fad = 0.2e-9

    def law(sep, adhesion):
        delta = np.clip(-sep, 0, None)
        return np.where(delta > 0, a * delta**exponent - adhesion, 0.0)

    force = np.concatenate([law(d, fad), law(d[::-1], fad + pull_off)])
    force = force + rng.normal(0, 0.01e-9, force.size)
    sep = np.concatenate([d, d[::-1]])
    deflection = -force / K
    return ForceCurve(force, z_piezo_m=sep + deflection, deflection_m=deflection,
                      segment=np.repeat([0, 1], d.size), spring_constant_n_per_m=K)


@pytest.mark.parametrize("exponent", [1.5, 2.0])
def test_free_exponent_and_contact_point_recovered(exponent):
    fit = ContactFit(exponent=None).fit(branch(synthetic(exponent), 0))
    assert fit.exponent_ == pytest.approx(exponent, abs=0.1)
    assert abs(fit.contact_point_m_) < 1.5e-9  # the true contact is at separation 0
    assert fit.adhesion_n_ == pytest.approx(0.2e-9, abs=0.05e-9)


def test_gain_on_the_retraction_only_when_the_exponent_is_wrong():
    cone = analyse_curve(synthetic(2.0, seed=1))
    sphere = analyse_curve(synthetic(1.5, seed=1))
    assert cone["gain"] > 0.3  # DMT sphere cannot predict a cone's retraction
    assert abs(sphere["gain"]) < 0.1  # nothing to gain when the baseline is right
    assert sphere["extended"]["exponent"] == pytest.approx(1.5, abs=0.1)


def test_adhesion_hysteresis_and_loop_work():
    plain = analyse_curve(synthetic(1.5, seed=2))
    neck = analyse_curve(synthetic(1.5, pull_off=0.5e-9, seed=2))
    assert plain["adhesion_hysteresis_n"] == pytest.approx(0.0, abs=0.05e-9)
    assert neck["adhesion_hysteresis_n"] == pytest.approx(0.5e-9, abs=0.05e-9)
    assert neck["loop_work_j"] > 10 * abs(plain["loop_work_j"])


@pytest.mark.parametrize("name", ["fmt-igor-fd_SiN_FD_plot.ibw",
                                  "fmt-jpk-fd_spot3-0192.jpk-force",
                                  "fmt-afm-workshop-fd_single_2021-10-22_14.16.csv"])
def test_real_curves_run_and_the_fits_are_physical(name):
    result = analyse_curve(open_recording(FORCE / name))
    for model in ("baseline", "extended"):
        assert result[model]["prefactor"] >= 0 and np.isfinite(result[model]["heldout_nrmse"])
    assert 1.0 <= result["extended"]["exponent"] <= 3.0
    # the free exponent never fits the approach worse than the fixed one
    assert result["extended"]["rms_approach_n"] <= result["baseline"]["rms_approach_n"] * 1.0001
    assert result["pull_off_n"] > 0  # every curve sticks on retraction
