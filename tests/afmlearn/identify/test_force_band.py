"""The force band of the output-error fit (afmlearn.identify.force_band): the delta method
against sampling, the profile envelope's rules, and its coverage of the true force on series
with a known law (where the Gauss--Newton band at the estimate's exponent misses it)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from afmlearn.identify.drive import RecordedPhase
from afmlearn.identify.force_band import Z95, conditional_band, conditional_force, profile_band
from afmlearn.identify.library import AFMLibrary, Indentation, InversePower, TermInput
from afmlearn.identify.output_error import (
    OutputErrorFit,
    OutputErrorLaw,
    OutputErrorProfile,
    OutputErrorResult,
)
from afmlearn.io import Experiment
from tests.afmlearn.identify.test_joint import _problem, _true_law
from tests.afmlearn.identify.test_joint_output_error import _series

LAW = OutputErrorLaw(library=AFMLibrary([Indentation(1.5), InversePower(2.0)]),
                     exponent_index=0)


def _result(p: float, a0: float, c: tuple[float, float], cov: np.ndarray | None = None,
            chi2: float = 100.0, dof: int = 100) -> OutputErrorResult:
    u = np.array([1.0, 0.01, 0.01, a0, p, *c])
    if cov is None:
        cov = np.zeros((u.size, u.size))
    return OutputErrorResult(law=LAW, u=u, phases=np.zeros(1), chi2=chi2, dof=dof,
                             converged=True, covariance=cov)


def _inputs(n: int = 400) -> list[TermInput]:
    z = np.linspace(-0.02, 0.2, n)
    return [TermInput(z=z, zdot=np.zeros(n), x=1.0 - z, a0=0.03)]


def test_delta_method_matches_sampling_of_the_covariance():
    """sd of F(t) from the covariance of (a0, c) at a fixed exponent against the spread of the
    force of 4,000 parameter draws (the plain reference); K, D, B, p are marginalised."""
    rng = np.random.default_rng(0)
    a = rng.normal(size=(7, 7))
    cov = a @ a.T * 1e-4
    cov[3, :] *= 0.05  # a0: a small spread (the delta method is first order in it)
    cov[:, 3] *= 0.05
    cov[4, :] = cov[:, 4] = np.nan  # the exponent fixed (a profile point)
    res = _result(1.5, 0.03, (2.0, -1e-4), cov)
    ti = _inputs()
    (f, sd), = conditional_force(res, ti)
    idx = [3, 5, 6]
    draws = rng.multivariate_normal(res.u[idx], cov[np.ix_(idx, idx)], size=4000)
    fs = np.array([LAW.library.evaluate(TermInput(z=ti[0].z, zdot=ti[0].zdot, x=ti[0].x,
                                                  a0=d[0])) @ d[1:] for d in draws])
    np.testing.assert_allclose(f, LAW.library.evaluate(
        TermInput(z=ti[0].z, zdot=ti[0].zdot, x=ti[0].x, a0=0.03)) @ res.u[5:])
    deep = ti[0].z < 0.02  # away from the onset's kink
    np.testing.assert_allclose(sd[deep], fs.std(axis=0)[deep], rtol=0.05)
    band = conditional_band(res, ti, simultaneous=False)
    np.testing.assert_allclose(band["hi"][0] - band["lo"][0], 2 * Z95 * sd)
    # simultaneous over a0 and the two coefficients: chi2_3(0.95) = 7.815
    band = conditional_band(res, ti)
    np.testing.assert_allclose(band["hi"][0] - band["lo"][0], 2 * math.sqrt(7.8147) * sd,
                               rtol=1e-4)


def test_free_exponent_covariance_is_conditioned_on_the_exponent():
    """With p free, the coefficient's variance that comes only through its correlation with p
    is removed (the profile's envelope carries p): a covariance whose c1 spread is all p's
    gives no width."""
    cov = np.zeros((7, 7))
    cov[4, 4], cov[5, 5], cov[4, 5] = 0.04, 0.01, 0.02  # c1 = 0.5 p exactly
    cov[5, 4] = 0.02
    (_, sd), = conditional_force(_result(1.5, 0.03, (2.0, 0.0), cov), _inputs())
    assert np.max(sd) < 1e-12


def test_profile_envelope_uses_points_inside_the_level_and_the_interpolated_ends():
    """Known answer: three zero-covariance profile points (p 1.3, 1.5, 1.7; rises 4 x level,
    0, 4 x level): the band is [F_1.5 + w (F_1.3 - F_1.5), F_1.5 + w (F_1.7 - F_1.5)] per
    sample with w = 1/2 (sqrt(rise) linear), and the outside points' own forces are not in it;
    a covariance at the estimate adds 1.96 sd (pointwise level 3.841); the simultaneous
    level (chi2_4 = 9.49 for a0, p and two coefficients) takes the 1.3 and 1.7 points' forces
    in at w = sqrt(9.49 / 15.36)."""
    level = Z95**2
    fits = {1.3: _result(1.3, 0.03, (2.0, 0.0)), 1.5: _result(1.5, 0.03, (2.0, 0.0)),
            1.7: _result(1.7, 0.03, (2.0, 0.0))}
    prof = np.array([[1.3, 4 * level], [1.5, 0.0], [1.7, 4 * level]]) + [0, 500.0]
    # score of the estimate: _bic of it (chi2 + n_u log n) is the table's minimum
    best = fits[1.5]
    shift = best.chi2 + best.u.size * math.log(best.dof + best.u.size) - 500.0
    prof[:, 1] += shift
    expo = {"profile": prof, "fits": fits, "level": level, "dispersion": 1.0}
    ti = _inputs()
    band = profile_band(expo, best, ti, simultaneous=False)
    assert band is not None
    f = {p: LAW.library_at(r.u).evaluate(ti[0]) @ r.u[5:] for p, r in fits.items()}
    lo_ref = np.minimum(f[1.5], np.minimum(f[1.5] + 0.5 * (f[1.3] - f[1.5]),
                                           f[1.5] + 0.5 * (f[1.7] - f[1.5])))
    hi_ref = np.maximum(f[1.5], np.maximum(f[1.5] + 0.5 * (f[1.3] - f[1.5]),
                                           f[1.5] + 0.5 * (f[1.7] - f[1.5])))
    np.testing.assert_allclose(band["lo"][0], lo_ref, atol=1e-12)
    np.testing.assert_allclose(band["hi"][0], hi_ref, atol=1e-12)
    assert band["exponents"] == [1.5]
    # the estimate's own Gauss--Newton band: sd of c_1 gives 1.96 sd delta^1.5 on top
    cov = np.zeros((7, 7))
    cov[5, 5] = 1e-2
    wide = dict(fits)
    wide[1.5] = _result(1.5, 0.03, (2.0, 0.0), cov)
    b2 = profile_band({**expo, "fits": wide}, wide[1.5], ti, simultaneous=False)
    assert b2 is not None
    d15 = np.maximum(0.03 - ti[0].z, 0.0) ** 1.5
    np.testing.assert_allclose(b2["hi"][0], np.maximum(hi_ref, f[1.5] + Z95 * 0.1 * d15),
                               atol=1e-12)
    b3 = profile_band(expo, best, ti)
    assert b3 is not None
    w = math.sqrt(9.4877 / (4 * level))
    ends = [f[1.5] + w * (f[q] - f[1.5]) for q in (1.3, 1.7)]
    np.testing.assert_allclose(b3["hi"][0], np.maximum(f[1.5], np.maximum(*ends)), atol=1e-6)


def _coverage(seed: int) -> tuple[float, float, float]:
    """Fraction of the repulsive samples whose true force (the simulator's law on the same
    denoised orbits) lies in the (simultaneous) profile band, in the pointwise Gauss--Newton
    band at the estimate's exponent (a0 and the coefficients), and the band width ratio
    profile / GN (median over repulsive samples)."""
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        path = _series(Path(d) / "s.h5", f"seed={seed}")
        pb = RecordedPhase().initial(_problem(Experiment.read(path)))
        lib, c, a0 = _true_law(path, pb.length_m)
    law = OutputErrorLaw(library=lib, exponent_index=next(
        j for j, t in enumerate(lib.terms) if isinstance(t, Indentation)))
    u0 = np.array([1.0, 1 / pb.quality_factor, pb.drive_amplitude, 1.5 * a0, 1.75, *(0.7 * c)])
    fit = OutputErrorFit(n_harmonics=30, n_out=256)
    meas = fit.measure(pb)
    res, _ = fit.solve(pb, meas, law, u0)
    prof, best = OutputErrorProfile(step=0.2, max_nfev=12).run(fit, pb, meas, [res])
    ins = [TermInput(z=o.gap - o.denoised.x, zdot=-o.denoised.v, x=o.denoised.x, a0=a0)
           for o in pb.observations]
    band = profile_band(prof, best, ins)
    gn = conditional_band(best, ins, simultaneous=False)
    assert band is not None
    inside = [0, 0]
    ratio, n = [], 0
    for i, ti in enumerate(ins):
        ft = lib.evaluate(ti) @ c
        rep = ft > 0
        n += int(rep.sum())
        for k, b in enumerate((band, gn)):
            inside[k] += int(np.sum(rep & (ft >= b["lo"][i]) & (ft <= b["hi"][i])))
        ratio.append(((band["hi"][i] - band["lo"][i]) / (gn["hi"][i] - gn["lo"][i]))[rep])
    return inside[0] / n, inside[1] / n, float(np.median(np.concatenate(ratio)))


@pytest.mark.slow
def test_profile_band_covers_the_true_force_where_the_gauss_newton_band_does_not():
    """test_joint's sphere series (6 set-points x 40 periods, noise 0.2 %) over noise seeds:
    the true force lies inside the profile band on >= 95 % of the repulsive samples of every
    seed; the Gauss--Newton band at the estimate's exponent (a0 and the coefficients) covers
    less than 95 % pooled (measured, seeds 0-3: 100 % each against 53 / 76 / 62 / 48 %; the
    interval 1.38-2.30 ... 1.24-1.81 for the true 1.5). ~6 s per seed."""
    cover, gn = [], []
    for seed in range(3):
        c_band, c_gn, ratio = _coverage(seed)
        cover.append(c_band)
        gn.append(c_gn)
        assert ratio > 1.0
    assert min(cover) >= 0.95, cover
    assert np.mean(gn) < 0.95, gn
