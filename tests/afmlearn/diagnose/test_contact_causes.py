"""The causes that act near contact (``contact_geometry``, ``adhesion_hysteresis``,
``electrostatic``) on small constructed set-point series.

Each strong case is a :class:`~afmlearn.diagnose.synthetic.SeriesCase` with chosen (not drawn)
parameters, simulated once; the diagnosis reads the file without its labels and the truth is
used only to check the answer. A clean strong case is named by its own hypothesis; its null
twin (the same lever, sample and set-points without the effect) is named by none of the
three. What the drawn benchmark series show (most cones and every drawn electrostatic series
are invisible at 200 samples per period and 1 % noise) is in docs/diagnose.md.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from afmlearn.diagnose import Diagnoser
from afmlearn.diagnose.hypotheses import AdhesionHysteresis, ContactGeometry, Electrostatic
from afmlearn.diagnose.hypotheses.adhesion_hysteresis import Neck
from afmlearn.diagnose.hypotheses.electrostatic import ElectrostaticTerm
from afmlearn.diagnose.synthetic import SeriesCase, simulate_series
from afmlearn.io import Experiment


def _case(causes: tuple[str, ...], effects: dict, *, setpoints: tuple[float, ...],
          reduced_modulus_pa: float, free_amplitude_m: float, tip_radius_m: float = 10e-9
          ) -> SeriesCase:
    return SeriesCase(causes=causes, quality_factor=250.0, free_amplitude_m=free_amplitude_m,
                      setpoints=setpoints, settle_offsets=(0.1, 0.4, 0.7, 0.9),
                      tip_radius_m=tip_radius_m, hamaker_j=1e-19,
                      reduced_modulus_pa=reduced_modulus_pa, a0_m=0.3e-9, effects=effects,
                      seed=5)


#: cone p = 2.2 (Sneddon coefficient, half angle 25 deg) on a soft polymer (E* 1 GPa): deep
#: indentation (up to 3.8 nm) that changes across the set-points
_CONE_P = 2.2
_SOFT = {"setpoints": (0.85, 0.65, 0.5, 0.35), "reduced_modulus_pa": 1e9,
         "free_amplitude_m": 15e-9}
CASES = {
    "contact_geometry": _case(
        ("contact_geometry",),
        {"contact_geometry": {"exponent": _CONE_P, "contact_coefficient": 2.0 / math.pi * 1e9
                              * math.tan(math.radians(25.0)) * (1e-9) ** (2.0 - _CONE_P)}},
        **_SOFT),
    "none": _case((), {}, **_SOFT),
    # JKR neck, w = 0.2 J/m^2 on a stiffer polymer, set-points deep enough to tap
    "adhesion_hysteresis": _case(
        ("adhesion_hysteresis",), {"adhesion_hysteresis": {"work_of_adhesion_j_per_m2": 0.2}},
        setpoints=(0.45, 0.4, 0.35, 0.3), reduced_modulus_pa=3e9, free_amplitude_m=20e-9,
        tip_radius_m=15e-9),
    # 4 V bias (KPFM-like): the deep set-points tap, the first one may stay attractive
    "electrostatic": _case(
        ("electrostatic",), {"electrostatic": {"voltage_v": 4.0}},
        setpoints=(0.5, 0.45, 0.4, 0.35), reduced_modulus_pa=2e9, free_amplitude_m=20e-9),
}


@pytest.fixture(scope="module")
def series(tmp_path_factory):
    """``series(name) -> path``: the constructed case simulated once (200 samples/period,
    20 periods per set-point, 1 % noise, drive phase recorded; neutral file name)."""
    folder = tmp_path_factory.mktemp("contact-causes")
    made: dict[str, Path] = {}

    def make(name: str) -> Path:
        if name not in made:
            path = folder / f"series-{len(made)}.h5"
            simulate_series(CASES[name], path, n_periods=20, noise_level=0.01)
            made[name] = path
        return made[name]

    return make


def _diagnose(path: Path, hypotheses) -> Diagnoser:
    return Diagnoser(hypotheses=hypotheses, max_causes=1).fit(Experiment.read(path))


def test_cone_series_is_named_with_an_exponent_above_the_sphere(series):
    """The cone is named from unseen set-points; its exponent interval excludes the
    sphere's 1.5 (the chi2 drop at the true law is 136, threshold 7.2)."""
    dg = _diagnose(series("contact_geometry"), [ContactGeometry()])
    assert dg.cause_ == "contact_geometry", dg.candidates_
    assert dg.gain_ > 0.3
    lo, hi = dg.exponent_interval_
    assert dg.exponent_bounded_ and 1.5 < lo <= dg.exponent_ <= hi


def test_neck_series_is_named(series):
    """A JKR neck (rate-independent loss at pull-off) is named by the neck extension (drop
    at the true neck 36, threshold 9.9), which the sample takes energy from."""
    dg = _diagnose(series("adhesion_hysteresis"), [AdhesionHysteresis()])
    assert dg.cause_ == "adhesion_hysteresis", dg.candidates_
    assert dg.gain_ > 0.05
    assert dg.extended_.spec.get(Neck) is not None


def test_electrostatic_series_is_named(series):
    """A 4 V bias is named although the sphere baseline absorbs part of it with a far-off
    a0 (drop at the true law 85, threshold 9.9)."""
    dg = _diagnose(series("electrostatic"), [Electrostatic()])
    assert dg.cause_ == "electrostatic", dg.candidates_
    assert dg.gain_ > 0.05
    r_nm = dg.extended_.spec.get(ElectrostaticTerm).radius * dg.extended_.scales.length * 1e9
    assert 1.0 <= r_nm <= 100.0


def test_null_twin_is_named_by_none_of_them(series):
    """The cone case without its effect (a sphere): none of the three causes."""
    dg = _diagnose(series("none"), [ContactGeometry(), AdhesionHysteresis(), Electrostatic()])
    assert dg.cause_ == "none", [(c.cause, c.delta_chi2, c.threshold) for c in dg.candidates_]


class _QuadraticProbe:
    """A probe whose chi-square profile is ``c + ((p - p0) / s)**2`` (known interval)."""

    traces: list = []

    def __init__(self, p0: float, s: float) -> None:
        self.p0, self.s = p0, s

    def profile(self, name, values):
        assert name == "contact_exponent"
        return np.array([100.0 + ((v - self.p0) / self.s) ** 2 for v in values])


class _FlatProbe(_QuadraticProbe):
    def profile(self, name, values):
        return np.full(len(values), 100.0)


class _Model:
    def __init__(self, p: float) -> None:
        from afmlearn.diagnose.spec import ModelSpec
        self.spec = ModelSpec(a0=0.03, contact_exponent=p)


def test_exponent_interval_is_the_profile_likelihood_interval():
    """95 % interval where the profile rises by 3.84: p0 +- 1.96 s for a parabola (ends
    interpolated linearly between the profile's steps)."""
    d = ContactGeometry().details(_Model(2.1), _QuadraticProbe(2.1, 0.2))
    lo, hi = d["exponent_interval"]
    assert d["bounded"]
    assert lo == pytest.approx(2.1 - 1.96 * 0.2, abs=0.02)
    assert hi == pytest.approx(2.1 + 1.96 * 0.2, abs=0.02)
    d = ContactGeometry().details(_Model(2.1), _FlatProbe(2.1, 0.2))
    assert not d["bounded"] and d["exponent_interval"] == [1.0, 3.5]
    assert "do not bound" in d["text"]
