"""Adding a cause is one hypothesis class, one extension class and a threshold: proved here
with a cause the library does not ship, defined ONLY in this file.

The cause ``squeeze_film``: hydrodynamic squeeze-film damping of a sphere approaching a plane
(Reynolds), ``F = c z'/z`` out of contact (``c = -6 pi eta R^2 <= 0``), which decays as
``1/z`` -- unlike the shipped ``long_range_damping`` (``exp(-z/z_b) z'``) and
``viscoelastic`` (in contact only). Its extension is a force term (:class:`AbstractForceTerm`,
hook ``term()``: the library's ``GapRate(p=-1)``, which the compiled kernel already
integrates); its hypothesis has no nonlinear parameter. Nothing in :mod:`afmlearn.diagnose`
is edited: the series is simulated with the simulator's own law (a test-only
:class:`AbstractForceModel` added to the drawn tip--sample force), the diagnosis is given the
extended hypothesis list and a null threshold for the new cause, and must name it on the
series that carries it and name nothing on its null twin (the same draw without it).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, final

import numpy as np
import pytest
from scipy import stats

import afmlearn.diagnose.synthetic as synthetic
from afmlearn.diagnose import Diagnoser, NullCalibration
from afmlearn.diagnose.hypotheses import (
    AbstractHypothesis,
    Context,
    DecayingDamping,
    DetectorMap,
    ElectrostaticTerm,
    Neck,
    Parameter,
    SecondMode,
    Viscoelastic,
    ViscoelasticTerm,
)
from afmlearn.diagnose.hypotheses.base import energy_text, gain_text
from afmlearn.diagnose.model import DiagnosisModel
from afmlearn.diagnose.spec import AbstractForceTerm, ModelSpec
from afmlearn.identify.library import GapRate
from afmlearn.io import Experiment
from simulator import Scales
from simulator.forces.base import AbstractForceModel
from simulator.forces.law import ForceLaw, Kind, Term

# ------------------------------------------------------------------ the new cause (all of it)


@final
@dataclass(frozen=True)
class SqueezeFilmTerm(AbstractForceTerm):
    """``c z'/z`` out of contact, ``c <= 0``."""

    key = "squeeze_film"

    def term(self) -> GapRate:
        return GapRate(p=-1.0, l=1)

    def report(self, scales: Scales) -> dict[str, Any]:
        return {"squeeze_film": "c z'/z"}


@final
class SqueezeFilm(AbstractHypothesis):
    """Add ``c z'/z`` out of contact (one linear coefficient)."""

    cause = "squeeze_film"
    extension = "squeeze-film damping z'/z"
    explanation = "energy is lost out of contact by a damping that decays as 1/gap"

    def parameters(self, ctx: Context) -> list[Parameter]:
        return []

    def extend(self, spec: ModelSpec, values: Sequence[float]) -> ModelSpec:
        return spec.with_extension(SqueezeFilmTerm())

    def evidence(self, model: DiagnosisModel, *, delta_chi2: float, gain: float,
                 energy=None) -> str:
        return (f"squeeze-film loss z'/z; chi2 drop {delta_chi2:.1f}, held-out gain "
                f"{gain_text(gain)}{energy_text(model, energy)}")


def _threshold(n_causes: int) -> float:
    """Its null threshold by the floor rule of the shipped calibration: the chi-square point
    of its parameter count (one coefficient) at a family-wise rate of 5 % over the causes."""
    return float(stats.chi2.ppf(1.0 - 0.05 / n_causes, 1))


# ------------------------------------------------------------------ hiding it in a series


@final
class _SqueezeFilmForce(AbstractForceModel):
    """Simulator side: ``F = -strength z'/z`` out of contact."""

    name = "squeeze_film"

    def __init__(self, *, strength: float) -> None:
        self.strength = float(strength)

    def law(self) -> ForceLaw:
        return ForceLaw((Term(Kind.GAP_RATE, -self.strength, -1.0, 1.0),))

    def _reference(self, z, zdot, contact):
        return np.where(contact, 0.0, -self.strength * zdot / z)

    def parameters(self) -> dict[str, Any]:
        return {"strength": self.strength}


#: ``-c`` [k L_ref / omega0]: at the rest gap (1 L_ref) the film damps like a lever of Q = 300,
#: near contact (a0 ~ 0.03 L_ref) some 30x more (a liquid). Measured on this draw: at 1/3000
#: and 1/1000 the visco-elastic term takes the loss near contact (it is named, drops 10.7
#: and 288 against the film's 0.6 and 152); at 1/300 the film is named (drop 12,252 against
#: 8,044, held-out gain 0.42) and its null twin names nothing
STRENGTH = 1.0 / 300


def hide(path, *, strength: float, seed: int = 4) -> None:
    """Simulate the seeded 4-set-point draw (20 periods, 200 samples per period, 1 % noise,
    drive phase recorded) with a film of ``strength`` (0: its null twin) added to the drawn
    tip--sample force."""
    real = synthetic._tip_sample_force

    def with_film(*args, **kwargs):
        return real(*args, **kwargs) + _SqueezeFilmForce(strength=strength)

    mp = pytest.MonkeyPatch()
    if strength > 0:
        mp.setattr(synthetic, "_tip_sample_force", with_film)
    try:
        synthetic.hidden_series(np.random.default_rng([seed, 78]), path, causes="none",
                                n_points=4, samples_per_period=200, n_periods=20,
                                noise_level=0.01, drive_phase=True)
    finally:
        mp.undo()


@pytest.fixture(scope="module")
def series(tmp_path_factory):
    """``series(hidden) -> path``: the draw with or without the hidden film."""
    folder = tmp_path_factory.mktemp("new-cause")
    made: dict[bool, Any] = {}

    def make(hidden: bool):
        if hidden not in made:
            made[hidden] = folder / f"series-{int(hidden)}.h5"
            hide(made[hidden], strength=STRENGTH if hidden else 0.0)
        return made[hidden]

    return make


def _diagnose(path) -> Diagnoser:
    hyps = [Viscoelastic(), SqueezeFilm()]
    default = NullCalibration.default("series")
    cal = NullCalibration(thresholds={**default.thresholds,
                                      "squeeze_film": _threshold(len(default.thresholds) + 1)},
                          min_gain=default.min_gain, source="shipped + squeeze_film floor")
    return Diagnoser(hypotheses=hyps, calibration=cal, max_causes=1).fit(Experiment.read(path))


# ------------------------------------------------------------------ tests


def test_new_cause_structure():
    """The new extension enters the model generically: one more column with the term's sign,
    a nested coefficient layout, the kernel's law encoding, the report -- no library edit."""
    base = ModelSpec(a0=0.03)
    ext = SqueezeFilm().extend(base, [])
    assert ext.term_keys() == ["vdw", "contact", "squeeze_film"] and ext.signs()[-1] == -1
    z = np.linspace(0.01, 2.0, 50)
    zd = np.cos(7 * z)
    col = ext.columns(z, zd)[:, -1]
    assert np.allclose(col, np.where(z > 0.03, zd / z, 0.0), rtol=1e-14, atol=0)
    coef = np.array([1.0, 0.003, 0.004, -1e-4, 2.0])
    assert np.array_equal(ext.embed(base, coef), [*coef, 0.0])
    model = DiagnosisModel(spec=ext, coef=np.array([*coef, -2e-6]), omega=1.0, gap=1.0,
                           scales=Scales(spring_constant=20.0, resonance_frequency=3e5,
                                         length=1e-8))
    kinds, p1 = model.kernel_args()[1:3]
    assert kinds[-1] == Kind.GAP_RATE and p1[-1] == -1.0
    assert model.parameters()["squeeze_film"] == "c z'/z" and "z^-1 z'" in model.equation()


def test_extensions_are_kept_in_one_canonical_order():
    """The same extensions added in any order give one spec (==, hash) and one column layout:
    role first, the shipped force terms in their historical order, a new one after them."""
    exts = [ViscoelasticTerm(exponent=0.5), DecayingDamping(decay=0.4),
            ElectrostaticTerm(radius=0.5), SqueezeFilmTerm(), Neck(length=0.1),
            SecondMode(frequency_ratio=6.3, quality_factor=400.0, force_gain=1.0),
            DetectorMap(b2=0.01, b3=0.0)]
    base = ModelSpec(a0=0.03)
    specs = []
    for seed in range(6):
        order = np.random.default_rng(seed).permutation(len(exts))
        spec = base
        for j in order:
            spec = spec.with_extension(exts[j])
        specs.append(spec)
        specs.append(ModelSpec(a0=0.03, extensions=tuple(exts[j] for j in order[::-1])))
    assert all(s == specs[0] and hash(s) == hash(specs[0]) for s in specs)
    assert len(set(specs)) == 1
    keys = ["vdw", "contact", "visco", "damping", "electrostatic", "squeeze_film", "neck"]
    assert all(s.term_keys() == keys for s in specs)
    assert [e.key for e in specs[0].extensions] == [*keys[2:], "mode2", "detector"]
    # replacing an extension keeps the layout; a different parameter is a different spec
    other = specs[0].with_extension(ViscoelasticTerm(exponent=0.7))
    assert other.term_keys() == keys and other != specs[0]


@pytest.mark.slow
def test_new_cause_is_named_and_its_null_twin_is_not(series):
    """The hidden film is named by its hypothesis with a held-out gain; the same draw without
    it is named by none of the causes tested (measured in docs/diagnose.md)."""
    dg = _diagnose(series(True))
    assert dg.cause_ == "squeeze_film", [(c.cause, c.delta_chi2, c.gain)
                                         for c in dg.candidates_]
    assert dg.gain_ > 0.05
    null = _diagnose(series(False))
    assert null.cause_ == "none", [(c.cause, c.delta_chi2, c.gain) for c in null.candidates_]
