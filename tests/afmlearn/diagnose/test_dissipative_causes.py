"""Known answers of the dissipative causes on set-point series: a loss out of contact is not
named a loss in contact, and vice versa (docs/diagnose.md, "The dissipative causes on
set-point series").

Constructed draws (every parameter chosen, not drawn; 4 set-points x 20 periods, 200
samples/period, 1 % noise, recorded drive phase): a long-range damping on a stiff sample
(5 GPa; 2e-7 N s/m decaying over 5 nm: it takes energy before the tip touches) and a
visco-elastic loss on a soft one (1 GPa; the generating law, DMT + ``eta sqrt(delta)
delta'``, is exactly the visco-elastic extension's family).
"""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.diagnose import Diagnoser
from afmlearn.diagnose.balance import Solution
from afmlearn.diagnose.diagnoser import tie_margin
from afmlearn.diagnose.fit import (
    energy_starts,
    fit_baseline,
    fit_extension,
    phase_starts,
    refine_output_error,
)
from afmlearn.diagnose.hypotheses import AdhesionHysteresis, LongRangeDamping, Viscoelastic
from afmlearn.diagnose.hypotheses.base import Context
from afmlearn.diagnose.synthetic import SeriesCase, simulate_series
from afmlearn.io import read_trace

N_POINTS = 4
COMMON = {"quality_factor": 300.0, "free_amplitude_m": 25e-9,
          "setpoints": tuple(np.linspace(0.85, 0.35, N_POINTS).tolist()),
          "settle_offsets": tuple((0.37 * k) % 1 for k in range(N_POINTS)),
          "tip_radius_m": 10e-9, "hamaker_j": 1e-19, "a0_m": 0.3e-9, "seed": 3}
CASES = {
    "long_range_damping": SeriesCase(
        causes=("long_range_damping",), reduced_modulus_pa=5e9,
        effects={"long_range_damping": {"coefficient_ns_per_m": 2e-7,
                                        "decay_length_m": 5e-9}}, **COMMON),
    "viscoelastic": SeriesCase(
        causes=("viscoelastic",), reduced_modulus_pa=1e9,
        effects={"viscoelastic": {"viscosity_si": 0.03}}, **COMMON),
}


@pytest.fixture(scope="module")
def constructed(tmp_path_factory):
    folder = tmp_path_factory.mktemp("dissipative")
    cache = {}

    def make(cause: str):
        if cause not in cache:
            path = folder / f"series-{len(cache)}.h5"
            simulate_series(CASES[cause], path, n_periods=20.0)
            dg = Diagnoser(hypotheses=[Viscoelastic(), LongRangeDamping(),
                                       AdhesionHysteresis()],
                           max_causes=1, all_gains=True).fit(read_trace(path))
            cache[cause] = dg
        return cache[cause]

    return make


def _cands(dg: Diagnoser) -> dict:
    return {c.cause: c for c in dg.candidates_}


def _conservative_point(dg: Diagnoser, cause: str) -> tuple[Solution, Context]:
    """The candidate's fit with its extension dropped (the conservative model at its point,
    shot by the diagnosis' output error) and the diagnosis' context (series: ``a0`` capped)."""
    sol = _cands(dg)[cause].solution
    keys = sol.spec.term_keys()
    base = sol.spec.replace(extensions=())
    coef = np.concatenate([sol.coef[:3], [sol.coef[3 + keys.index(k)] for k in
                                          base.term_keys()], sol.coef[3 + len(keys):]])
    r, _, phases = dg._oe.residual(base, coef)
    scales = dg._obs[0].cal.scales
    ctx = Context(length_m=scales.length, amplitude=1.0, z_min=0.0, z_max=2.0,
                  tip_radius=10e-9 / scales.length, a0_max=3e-9 / scales.length)
    return Solution(spec=base, coef=coef, residual=r, chi2=float(r @ r),
                    values=(sol.values[0],), phases=tuple(phases)), ctx


def test_energy_balance_finds_the_decay_length(constructed):
    """Known answer of ``fit.energy_starts`` (no refinement): the loss per set-point (drive
    input minus the lever's loss, from the calibrated lever and the recorded phases) is carried
    best by one damping coefficient at a decay length next to the generating one (5 nm; the
    grid's points are 1.5x apart), with the column's sign (c <= 0), and not by the grid's
    shortest (1 nm), where the diagnosis' own damping fits sit. The starts are shot from the
    orbits the output error held on entry and leave them held: called twice, the same starts
    (the session-6 start was shot from the orbits its previous call had left)."""
    dg = constructed("long_range_damping")
    current, ctx = _conservative_point(dg, "long_range_damping")
    oe = dg._oe
    held = oe.snapshot()
    first = energy_starts(oe, current, LongRangeDamping(), ctx, max_nfev=0)
    assert oe.snapshot()[0].keys() == held[0].keys()
    assert all(np.array_equal(oe.snapshot()[0][k][0], v[0]) for k, v in held[0].items())
    again = energy_starts(oe, current, LongRangeDamping(), ctx, max_nfev=0)
    assert [s.chi2 for s in first] == [s.chi2 for s in again]
    assert len(first) == LongRangeDamping.energy_scan
    decay_m = [s.values[1] * ctx.length_m for s in first]
    scanned = [s.values[1] for s in first]
    assert all(3e-9 < d < 8e-9 for d in decay_m), decay_m
    for s, zb in zip(first, scanned, strict=True):
        j = s.spec.term_keys().index("damping")
        assert s.coef[3 + j] < 0, (zb, s.coef)


def test_phase_starts_adds_the_recorded_phases_only_when_they_differ():
    """``fit.phase_starts``: the base model's phases, plus the recorded ones (the priors'
    means) when every observation has one and one differs by more than ``tol`` (mod 2 pi)."""
    base = Solution(spec=None, coef=np.zeros(3), residual=np.zeros(1), chi2=1.0, values=(),
                    phases=(0.1, -3.0))

    class _Joint:
        def __init__(self, priors):
            self.phase_priors = priors

    assert phase_starts(_Joint([None, (-3.0, 0.02)]), base) == [(0.1, -3.0)]
    # 2 pi apart is the same phase
    assert phase_starts(_Joint([(0.1 + 2 * np.pi, 0.02), (-3.0, 0.02)]), base) == [(0.1, -3.0)]
    assert phase_starts(_Joint([(0.1, 0.02), (-2.5, 0.02)]), base) == [(0.1, -3.0),
                                                                         (0.1, -2.5)]


def test_extension_grid_starts_from_the_recorded_phases(constructed):
    """Known answer of the equation-error start (``fit.fit_extension``) of the damping term:
    the drawn decay length (5 nm) and onset (0.3 nm). A conservative baseline can balance the
    drive's energy only by shifting the drive phases (here by more than 0.5 rad from the
    recorded ones, prior SD 0.02 rad), and from its phases the grid put the damping at 13 nm
    and ``a0`` at 1.1 nm (equation error 30,960; measured before the fix); from the recorded
    phases it is at the drawn law (163). Session 8: on seed-2026 damping series the damping
    fits ended 600-11,000 above the drawn law refitted for this reason."""
    dg = constructed("long_range_damping")
    _, ctx = _conservative_point(dg, "long_range_damping")
    jb = dg._jb
    base = fit_baseline(jb, ctx)
    recorded = np.array([p[0] for p in jb.phase_priors])
    off = np.abs(np.angle(np.exp(1j * (np.asarray(base.phases) - recorded))))
    assert off.max() > 0.5, off             # the premise: the baseline's phases moved off
    assert len(phase_starts(jb, base)) == 2
    start = fit_extension(jb, base, LongRangeDamping(), ctx, n_starts=2, max_nfev=60)[0]
    a0_m, decay_m = (v * ctx.length_m for v in start.values)
    assert 4e-9 < decay_m < 6.5e-9, decay_m
    assert 0.2e-9 < a0_m < 0.45e-9, a0_m
    keys = start.spec.term_keys()
    assert start.coef[3 + keys.index("damping")] < 0
    assert start.coef[3 + keys.index("contact")] > 0


def test_baseline_leaves_a_soft_equation_error_start(constructed):
    """The baseline's output-error stage does not stay where a poor equation-error start put
    it: with the start's contact stiffness 30x too soft (as measured on a seed-2026 neck series
    redrawn with new noise: equation-error stiffness ~25x below the fitted one, the baseline
    stuck at chi2 50,144 and 8.4e6 against 584 on the original noise), the refinement also
    starts from a grid of physical laws (``fit.baseline_grid_starts``) and reaches the
    diagnosis' own baseline. Measured before the grid: 211,333 from this start (the
    diagnosis' baseline then 4,887; with the grid 2,618)."""
    dg = constructed("long_range_damping")
    _, ctx = _conservative_point(dg, "long_range_damping")
    base = fit_baseline(dg._jb, ctx)
    coef = np.array(base.coef, float)
    j = 3 + base.spec.term_keys().index("contact")
    coef[j] /= 30.0
    soft = Solution(spec=base.spec, coef=coef, residual=base.residual, chi2=base.chi2,
                    values=base.values, phases=base.phases)
    sol, _, _, _ = refine_output_error(dg._oe, [soft], None, soft, ctx, max_nfev=60)
    assert sol.chi2 <= 1.01 * dg.baseline_chi2_, (sol.chi2, dg.baseline_chi2_)


def test_damping_out_of_contact_is_not_named_viscoelastic(constructed):
    """The damping term explains the loss (measured: chi2 drop 4,722 against the visco-elastic
    term's 1,663, held-out gain 0.54 against 0.02): the in-contact term cannot take a loss that
    starts before contact, so the two are not even tied. The baseline (chi2 19,972) is
    re-based on the neck's point (5,487) and the damping fit (17,525 from the poor baseline)
    is refitted from there (765). Regression test of f9218b0: before it, the visco-elastic
    fit (3,824) kept its drop against the old baseline (16,148 instead of 1,663) and led the
    evidence; only its held-out gain (0.016, below 0.05) kept it from being named. Since the
    JKR neck (4ec2933) the neck's fit no longer re-bases the baseline here and, from the grid
    scan's starts, visco-elastic was named (damping ~6,400, visco ~6,300); the damping term's
    energy-balance starts (session 7) find the decay length and reach ~190."""
    dg = constructed("long_range_damping")
    c = _cands(dg)
    assert dg.cause_ == "long_range_damping", dg.candidates_
    damping, visco = c["long_range_damping"], c["viscoelastic"]
    assert damping.score > visco.score + tie_margin(damping.delta_chi2), dg.candidates_


@pytest.mark.slow
def test_viscoelastic_loss_is_not_named_damping(constructed):
    """The generating law is in the visco-elastic family (its refit from the truth: chi2 162
    for 4 x 83 rows), so the visco-elastic extension should reach the noise and be named.
    Measured (session 6): the conservative baseline moves the contact onset out (7x the true
    one) to mimic the loss, and from there the equation error gives a coefficient far below
    the truth's (11,938; the damping term, 223, was named). The energy-balance start
    (``fit.energy_starts``: the coefficient from drive input minus lever loss per set-point)
    reached 168 in one run and 332 in another: it was shot from whatever orbits the output
    error held, and where two stable orbits coexist the shooting start picks the branch (the
    same visco-elastic point: chi2 248 shot cold, 6,617 from the orbits held last). Now every
    start of a joint fit is shot from the current model's orbits and cold (from the measured
    ones), the better kept (``fit._branch``), and the energy starts from the orbits held on
    entry (session 7: 167.6, named visco, in both hypothesis orders; on five further noise
    seeds the visco series is named visco 5/5 in both orders, 3/5 before)."""
    dg = constructed("viscoelastic")
    c = _cands(dg)
    assert dg.cause_ == "viscoelastic", dg.candidates_
    # the visco-elastic fit reaches the noise: as good as the damping term's, or better
    assert c["viscoelastic"].chi2 <= 1.1 * c["long_range_damping"].chi2, dg.candidates_
    assert c["viscoelastic"].gain > 0.5
