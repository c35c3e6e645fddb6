"""Hidden-effect tests (issues 5 and 12): one effect of the vocabulary, or none, or two at once,
switched on by a seeded draw the diagnosis cannot see; it must name it with a positive held-out
gain. Single orbits (issue 5) and set-point series (issue 12: one joint model over every
set-point, the gain measured on set-points the model was not fitted on).

The draw (cause and every parameter: Q 150-450, free amplitude 1.2-1.8 gaps, tip radius,
Hamaker constant, E*, a0, the effect's strength) happens inside
:func:`afmlearn.diagnose.synthetic.hidden_trace` from the test's generator; the trace file's
name is neutral and the diagnosis reads it without its labels. The truth is compared only
afterwards.

Two causes are held to a weaker standard per trace, for measured reasons (docs/diagnose.md,
docs/benchmarks.md):

* ``contact_geometry``: with a0 and the stiffness free, a steady tapping orbit does not
  determine the contact exponent (chi2 drop < 0.5 for cones of exponent 2.3-2.65 at 1,000
  samples per period); the effect must not be blamed on another cause (``none`` or itself).
* the dissipative causes (``viscoelastic``, ``long_range_damping``, ``adhesion_hysteresis``)
  all take energy near the lower turning point; on one orbit at 200 samples per period their
  penalised evidences often tie (e.g. 32.6 / 31.1 / 29.5 on fast draw 2, a long-range
  damping with a 2.6 nm decay). Per trace the fast test requires a dissipative cause with a
  positive gain; which channel is checked by rate in the slow test (exact cause) and in the
  benchmark's confusion matrix.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from afmlearn.diagnose import CAUSES, Diagnoser
from afmlearn.diagnose.synthetic import hidden_series, hidden_trace
from afmlearn.io import Experiment, read_trace


def _diagnose(tmp_path, seed: list[int], *, cause: str | None = None, spp: int = 200,
              noise: float = 0.01):
    path = tmp_path / f"recording-{'-'.join(map(str, seed))}.h5"
    case = hidden_trace(np.random.default_rng(seed), path, cause=cause,
                        samples_per_period=spp, n_periods=300, noise_level=noise)
    dg = Diagnoser().fit(read_trace(path))          # no labels, no file name
    return case, dg


DISSIPATIVE = ("viscoelastic", "long_range_damping", "adhesion_hysteresis")


def _check(case, dg, *, exact: bool = True) -> None:
    truth = case.cause
    msg = (f"truth {truth} {case.effect}, named {dg.cause_} (gain {dg.gain_:.3f}); "
           + ", ".join(f"{c.cause} {c.delta_chi2:.1f}/{c.threshold:.1f}/{c.gain:+.3f}"
                       for c in dg.candidates_))
    if truth == "none":
        assert dg.cause_ == "none", msg
    elif truth == "contact_geometry":
        assert dg.cause_ in ("none", "contact_geometry"), msg
    elif truth in DISSIPATIVE and not exact:
        assert dg.cause_ in DISSIPATIVE, msg
        assert dg.gain_ > 0.0, msg
        assert dg.extended_nrmse_ < dg.baseline_nrmse_, msg
    else:
        assert dg.cause_ == truth, msg
        assert dg.gain_ > 0.0, msg
        assert dg.extended_nrmse_ < dg.baseline_nrmse_, msg


@pytest.mark.parametrize("draw", range(4))
def test_hidden_effect_fast(tmp_path, draw):
    case, dg = _diagnose(tmp_path, [20261124, draw])
    _check(case, dg, exact=False)


@pytest.mark.parametrize("draw", range(2))
def test_null_trace_fast(tmp_path, draw):
    case, dg = _diagnose(tmp_path, [4242, draw], cause="none")
    _check(case, dg)


#: share of the six detectable effects named right at 1,000 samples per period and 0.5 %
#: noise in the benchmark (docs/benchmarks.md, section diagnose: 50 of 60 traces)
BENCHMARK_RATE = 50 / 60


@pytest.mark.slow
def test_hidden_effects_every_cause(tmp_path):
    """Two random draws per cause at 1,000 samples per period and 0.5 % noise (the issue's
    accurate setting): every null trace ``none``; no ``contact_geometry`` trace blamed on
    another cause; and the number of the other effects named exactly right, with a positive
    gain, not significantly below the benchmark's rate (one-sided binomial test at 1 %: with
    12 draws a count of 8, seen here, is an ordinary outcome of an 83 % rate; 6 or fewer
    is not)."""
    right, total, failures = 0, 0, []
    for cause in CAUSES:
        for draw in range(2):
            case, dg = _diagnose(tmp_path, [777, draw], cause=cause, spp=1000, noise=0.005)
            if cause in ("none", "contact_geometry"):
                _check(case, dg)
                continue
            total += 1
            ok = dg.cause_ == cause and dg.gain_ > 0
            right += ok
            if not ok:
                failures.append(f"{cause} -> {dg.cause_} ({dg.gain_:+.3f})")
    p_value = stats.binom.cdf(right, total, BENCHMARK_RATE)
    assert p_value >= 0.01, f"{right}/{total} (p = {p_value:.3g}): {failures}"


# ---------------------------------------------------------------------- set-point series
def _diagnose_series(tmp_path, seed: list[int], *, causes: str | None = None,
                     n_points: int = 3, spp: int = 200, periods: float = 20,
                     noise: float = 0.01):
    path = tmp_path / f"series-{'-'.join(map(str, seed))}.h5"
    case = hidden_series(np.random.default_rng(seed), path, causes=causes, n_points=n_points,
                         samples_per_period=spp, n_periods=periods, noise_level=noise)
    dg = Diagnoser().fit(Experiment.read(path))       # no labels, no file name
    return case, dg


def _found(dg) -> list[str]:
    return [s.cause for s in dg.causes_]


def _check_series(case, dg, *, exact: bool = True, complete: bool = True) -> None:
    truth = case.causes
    msg = (f"truth {case.cause} {case.effects}, named {_found(dg)} (gain {dg.gain_:.3f}); "
           + ", ".join(f"{c.cause} {c.delta_chi2:.1f}/{c.threshold:.1f}/{c.gain:+.3f}"
                       for c in dg.candidates_))
    if not truth:
        assert dg.cause_ == "none" and _found(dg) == [], msg
        return
    found = _found(dg)
    assert dg.cause_ == (found[0] if found else "none"), msg
    assert len(set(found)) == len(found), msg                 # each cause named once
    if exact:
        if complete:
            assert set(truth) <= set(found), msg
        assert dg.cause_ in truth, msg                        # the first one is real
    else:                                                      # the dissipative family ties
        fam = set(DISSIPATIVE)
        for t in truth:
            assert t in found or (t in fam and fam & set(found)), msg
    assert dg.gain_ > 0.0 and dg.extended_nrmse_ < dg.baseline_nrmse_, msg
    for s in dg.causes_:
        assert math.isfinite(s.gain), msg


def test_hidden_series_null_fast(tmp_path):
    """A null series (the baseline is the truth): no cause, in no step."""
    case, dg = _diagnose_series(tmp_path, [51, 0], causes="none")
    _check_series(case, dg)


@pytest.mark.parametrize("causes", [
    "higher_mode+detector_nonlinearity",
    # a cause the seed picks: ~60 s on one core, so not in the fast subset's budget
    pytest.param(None, marks=pytest.mark.slow)])
def test_hidden_series_fast(tmp_path, causes):
    """Two effects at once (a second mode and the detector, which one orbit already names
    reliably: issue 5, 90-100 %) and one draw whose cause the seed picks (hidden from the
    test's author too; the dissipative family may tie on three set-points).

    For the pair the first cause named must be one of the two, with a held-out gain; that
    both are found is checked by rate in the slow test and the benchmark (measured on this
    draw, 3 set-points: the detector first, then ``contact_geometry`` instead of the second
    mode at f2/f0 = 6.29)."""
    case, dg = _diagnose_series(tmp_path, [52, 0 if causes else 3], causes=causes)
    _check_series(case, dg, exact=causes is not None, complete=False)


#: measured share of effect series (single causes and pairs) named exactly right, with a
#: positive gain, at 200 samples per period, 1 % noise, 8 set-points of 30 periods with the
#: drive phase (docs/benchmarks.md, section diagnose_series: 9 of 24 draws); the slow test
#: below checks that a fresh set of draws is not significantly worse
SERIES_RATE = 9 / 24


@pytest.mark.slow
def test_hidden_series_every_cause(tmp_path):
    """One 8-set-point draw per cause and two two-effect draws, 200 samples per period and 1 %
    noise: the null series ``none``; the effects found exactly (all of a pair) at a rate not
    significantly below :data:`SERIES_RATE` (one-sided binomial test at 1 %)."""
    right, total, failures = 0, 0, []
    labels = [*CAUSES, "viscoelastic+electrostatic", "higher_mode+contact_geometry"]
    for draw, causes in enumerate(labels):
        case, dg = _diagnose_series(tmp_path, [61, draw], causes=causes, n_points=8,
                                    periods=30)
        if causes == "none":
            _check_series(case, dg)
            continue
        total += 1
        ok = set(case.causes) <= set(_found(dg)) and dg.cause_ in case.causes \
            and dg.gain_ > 0
        right += ok
        if not ok:
            failures.append(f"{case.cause} -> {_found(dg)} ({dg.gain_:+.3f})")
    p_value = stats.binom.cdf(right, total, SERIES_RATE)
    assert p_value >= 0.01, f"{right}/{total} (p = {p_value:.3g}): {failures}"
