"""The single-orbit problem and stages: immutability, pure designs, the drive rotation."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from afmlearn.identify.constraints import CalibrationConstraints
from afmlearn.identify.joint import Bagging
from afmlearn.identify.library import AFMLibrary, ContactIndicator, Indentation, InversePower
from afmlearn.identify.single import (
    DrivePhaseChoice,
    HeldoutStateError,
    OrbitExponentProfile,
    OrbitNoiseScale,
    OrbitOnsetProfile,
    OrbitRefinement,
    OrbitSelection,
    ParetoChoice,
    orbit_model,
)
from afmlearn.identify.single_problem import N_LIN, build_orbit_problem
from afmlearn.io import read_trace
from afmlearn.preprocess import calibrate

LIB = AFMLibrary([InversePower(2.0), ContactIndicator(), Indentation(1.5)])
LIB2 = AFMLibrary([InversePower(2.0), Indentation(2.5)])


@pytest.fixture(scope="module")
def problem(tmp_path_factory):
    """DMT tapping, 0.5 % noise, 40 periods x 200 samples, bound to its harmonic-balance rows."""
    from afmlearn.simulate import simulate
    from tests.afmlearn.conftest import _compose  # noqa: PLC0415 - shared composer

    out = tmp_path_factory.mktemp("dmt") / "dmt.h5"
    simulate(_compose([f"output={out}", "force=dmt", "noise.level=0.005",
                       "scenario.samples_per_period=200", "scenario.n_periods=40"]))
    return build_orbit_problem(
        calibrate(read_trace(out)), constraints=CalibrationConstraints(), projection=None,
        heldout_fraction=0.3, n_folds=4, max_harmonics=100, min_harmonics=30, thresholds=None,
        nus=None, n_a0=6, a0_range_m=(0.1e-9, 3e-9), physical_signs=True)


def test_design_is_a_pure_function_of_library_and_a0(problem):
    """Another design in between changes nothing: no optimizer state is left behind."""
    a0 = float(problem.a0_grid[len(problem.a0_grid) // 2])
    d1 = problem.design(LIB, a0)
    problem.design(LIB2, 2 * a0)
    d2 = problem.design(LIB, a0)
    for f in ("theta", "y", "lower", "upper", "pattern"):
        np.testing.assert_array_equal(getattr(d1, f), getattr(d2, f))
    o1, o2 = problem.optimizer(d1), problem.optimizer(d2)
    assert o1.threshold == o2.threshold == problem.thresholds[0]
    np.testing.assert_array_equal(o1.lower, d1.lower)


def test_new_problems_leave_the_old_one_unchanged(problem):
    rot = problem.with_drive(0.7, rotated=True)
    noisy = rot.with_noise(2.5)
    assert (problem.rotation, problem.drive_rotated, problem.noise_variance) == (0.0, False, None)
    assert (rot.rotation, rot.drive_rotated, rot.noise_variance) == (0.7, True, None)
    assert noisy.noise_variance == 2.5 and noisy.bound is problem.bound
    with pytest.raises(dataclasses.FrozenInstanceError):
        problem.rotation = 1.0  # type: ignore[misc]


@pytest.mark.parametrize("stage", [OrbitNoiseScale(), OrbitOnsetProfile(), DrivePhaseChoice(),
                                   OrbitSelection(), ParetoChoice(), HeldoutStateError(),
                                   OrbitRefinement(), OrbitExponentProfile(), Bagging()])
def test_stages_are_frozen_and_final(stage):
    assert getattr(type(stage), "__final__", False)
    field = dataclasses.fields(stage)[0].name if dataclasses.fields(stage) else "x"
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(stage, field, None)


def test_drive_rotation_leaves_the_identified_drive_unchanged(problem):
    """With a free drive, rotating its columns by phi is a change of basis: the fitted
    ``B cos(Omega tau - phase)`` is the same; boxing it holds ``B_c`` about ``F_c``."""
    a0 = float(problem.a0_grid[len(problem.a0_grid) // 2])
    pb0 = OrbitNoiseScale().run(problem, LIB, a0)
    assert pb0.noise_variance > 0
    models = []
    for phi in (0.0, 1.1, -2.5):
        pb = pb0.with_drive(phi, rotated=False)
        des = pb.design(LIB, a0)
        coef = pb.refit(des, np.ones(des.theta.shape[1], bool))
        models.append(orbit_model(pb, LIB, a0, coef))
    for m in models[1:]:
        assert m.drive_amplitude == pytest.approx(models[0].drive_amplitude, rel=1e-6)
        assert math.remainder(m.drive_phase - models[0].drive_phase, 2 * math.pi) \
            == pytest.approx(0.0, abs=1e-6)
        # the force coefficients are ill-conditioned (near-collinear terms); the force is not
        d = problem.denoised
        f0, f = (mm.force(1.0 - d.x, -d.v, d.x) for mm in (models[0], m))
        assert np.max(np.abs(f - f0)) < 1e-4 * np.ptp(f0)  # solver tolerance (measured 2e-5)
    fc = problem.calibrated.drive_amplitude
    tb = problem.constraints.box("drive")
    des = pb0.with_drive(0.3, rotated=True).design(LIB, a0)
    assert des.lower[2] == pytest.approx(fc * (1 - tb)) and des.upper[2] == pytest.approx(
        fc * (1 + tb))
    assert (des.lower[3], des.upper[3]) == (-fc * tb, fc * tb)
    assert np.all(des.lower[N_LIN:][[2]] == 0.0)  # the contact term repels


def test_drive_phase_choice_rotates_and_reports_its_candidates(problem):
    """The chosen phase is one of the scored candidates and the drive is boxed after it."""
    a0 = float(problem.a0_grid[len(problem.a0_grid) // 2])
    pb = OrbitNoiseScale().run(problem, LIB, a0)
    out, cands = DrivePhaseChoice().run(pb, LIB, a0)
    assert out.drive_rotated and out.noise_variance == pb.noise_variance
    assert len(cands) >= 2
    assert min(abs(math.remainder(out.rotation - p, 2 * math.pi)) for p, _ in cands) == 0.0
