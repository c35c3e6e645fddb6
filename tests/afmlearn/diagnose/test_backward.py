"""The backward check of named causes (docs/diagnose.md, "Backward check of named causes").

After the step-by-step search, every named cause is removed from the final model (the rest
refitted without it, the last named first); a cause whose removal does not raise chi2 above
its threshold, or whose held-out gain in the final model is not above ``min_gain``, is
dropped, until a pass drops nothing. Unit tests of the decision on constructed chi2 numbers,
then end to end: the session-6 demo's hidden strong long-range damping (named first, then a
neck whose coefficient in the final model was ~1e-16) and a two-effect series whose two real
causes must both stay named.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from afmlearn.diagnose import Diagnoser
from afmlearn.diagnose.backward import backward_eliminate, backward_keep, overwhelming
from afmlearn.diagnose.hypotheses import DetectorNonlinearity, LongRangeDamping, Viscoelastic
from afmlearn.diagnose.observation import read_experiment
from afmlearn.diagnose.report import report_markdown, report_record
from afmlearn.diagnose.synthetic import SeriesCase, series_files, simulate_series
from afmlearn.io import read_trace

MIN_GAIN = 0.05


# ---------------------------------------------------------------------- the decision
def test_backward_keep_reads_the_rise_then_the_gain():
    assert backward_keep(50.0, 9.88, 0.3, MIN_GAIN) == ""
    assert "chi2 rises by 9.9" in backward_keep(9.88, 9.88, 0.3, MIN_GAIN)   # not above
    assert "chi2" in backward_keep(-3.0, 9.88, math.nan, MIN_GAIN)    # refit went lower
    assert "chi2" in backward_keep(math.nan, 9.88, 0.3, MIN_GAIN)     # no evidence
    assert "held-out gain +0.050" in backward_keep(50.0, 9.88, 0.05, MIN_GAIN)
    assert "held-out gain" in backward_keep(50.0, 9.88, math.nan, MIN_GAIN)
    assert "held-out gain" in backward_keep(50.0, 9.88, -math.inf, MIN_GAIN)


def test_an_overwhelming_rise_is_not_refuted_by_the_heldout_gain():
    """The damping + detector dev draw [3, 78] of session 7 (visco named first, wrongly): the
    detector's removal raised chi2 by 35,865 (threshold 9.88) in a final model of chi2 3,952
    whose held-out predictions were poor (gain -0.895). The gain refutes over-fits, rises
    near the threshold, in the units of the final model's misfit; not this one."""
    disp = 3952.0 / 330.0                     # chi2 per residual row of that final model
    assert overwhelming(35865.0, 9.88, disp)
    assert backward_keep(35865.0, 9.88, -0.895, MIN_GAIN, dispersion=disp) == ""
    # the same rise in a final model that misses the data by 100x its noise is not
    assert not overwhelming(35865.0, 9.88, 400.0)
    assert "held-out gain -0.895" in backward_keep(35865.0, 9.88, -0.895, MIN_GAIN,
                                                   dispersion=400.0)
    # an over-fit: a rise of a few thresholds is still refuted by its gain, whatever the
    # misfit scale (values below 1 count as 1: an over-fit of noise is not excused)
    for d in (0.2, 1.0, 5.0):
        assert "held-out gain" in backward_keep(60.0, 9.88, -0.1, MIN_GAIN, dispersion=d)
    assert not overwhelming(98.8, 9.88, 0.5) and overwhelming(98.9, 9.88, 0.5)
    assert not overwhelming(1e9, 9.88, math.nan)          # no misfit scale: no override
    # the rise test itself is unchanged: an overwhelming-looking gain does not save a cause
    # whose removal does not raise chi2
    assert "chi2 rises" in backward_keep(5.0, 9.88, 0.9, MIN_GAIN, dispersion=1.0)


def test_backward_keeps_an_overwhelming_cause_with_a_note():
    f = frozenset
    chi2 = {f({0, 1}): 3952.0, f({0}): 39817.0, f({1}): 20789.0, f(): 56654.0}
    remove, accept, calls, gain_calls, accepted = _table(
        chi2, {(1, (0, 1)): -0.895}, dispersion=3952.0 / 330.0)
    kept, dropped, last = backward_eliminate(["viscoelastic", "detector_nonlinearity"],
                                             [7.24, 9.88], MIN_GAIN, remove, accept)
    assert kept == [0, 1] and dropped == [] and accepted == []
    assert last[1].kept and last[1].gain == -0.895
    assert "held-out gain in the final model is -0.895" in last[1].note
    assert "35865" in last[1].note and "another of its causes" in last[1].note
    assert last[0].note == ""                 # no conflict: no note
    # the same numbers at the noise level's misfit scale of a small over-fit: dropped
    chi2 = {f({0, 1}): 300.0, f({0}): 330.0, f({1}): 5000.0, f(): 9000.0}
    remove, accept, calls, gain_calls, accepted = _table(chi2, {(1, (0, 1)): -0.895})
    kept, dropped, last = backward_eliminate(["viscoelastic", "detector_nonlinearity"],
                                             [7.24, 9.88], MIN_GAIN, remove, accept)
    assert kept == [0] and [d.cause for d in dropped] == ["detector_nonlinearity"]
    assert dropped[0].note == "" and "held-out gain -0.895" in dropped[0].reason


def _table(chi2: dict[frozenset, float], gains: dict[tuple, float] | None = None, *,
           dispersion: float = 1.0):
    """A constructed experiment: the chi2 of the model of each set of kept causes, and the
    held-out gain of a cause in a final model (default 0.5); the final model's misfit scale;
    records every call."""
    calls: list[tuple[int, tuple[int, ...]]] = []
    gain_calls: list[int] = []
    accepted: list[int] = []

    def remove(i, kept):
        calls.append((i, kept))
        rise = chi2[frozenset(kept) - {i}] - chi2[frozenset(kept)]

        def gain():
            gain_calls.append(i)
            return (gains or {}).get((i, kept), 0.5), math.nan     # (NRMSE gain, no own)

        return rise, gain, dispersion

    return remove, accepted.append, calls, gain_calls, accepted


def test_backward_drops_causes_that_the_final_model_does_not_need():
    """The demo's pattern: damping named first (drop 1e5), then a neck and a mode whose steps
    won by the refit of the shared parameters; in the final model neither column matters.
    The last named is checked first; after each drop the next is checked against the new
    final model; the first cause stays."""
    f = frozenset
    chi2 = {f({0, 1, 2}): 800.0, f({0, 1}): 801.5, f({0, 2}): 1300.0, f({1, 2}): 9e4,
            f({0}): 802.0, f({1}): 9.1e4, f({2}): 9.2e4, f(): 1.2e5}
    remove, accept, calls, gain_calls, accepted = _table(chi2)
    kept, dropped, last = backward_eliminate(
        ["long_range_damping", "adhesion_hysteresis", "higher_mode"], [9.88, 9.88, 12.07],
        MIN_GAIN, remove, accept)
    assert kept == [0]
    assert [d.cause for d in dropped] == ["higher_mode", "adhesion_hysteresis"]
    assert accepted == [2, 1]
    assert dropped[0].chi2_rise == pytest.approx(1.5) and dropped[0].threshold == 12.07
    assert dropped[1].chi2_rise == pytest.approx(0.5) and not dropped[1].kept
    assert all(math.isnan(d.gain) for d in dropped)   # the rise decided: no held-out refits
    # each check against the final model of its time
    assert calls == [(2, (0, 1, 2)), (1, (0, 1)), (0, (0,))]
    assert gain_calls == [0]
    assert last[0].kept and last[0].chi2_rise == pytest.approx(1.2e5 - 802.0)


def test_backward_keeps_real_causes_in_one_pass():
    f = frozenset
    chi2 = {f({0, 1}): 300.0, f({0}): 5000.0, f({1}): 7000.0, f(): 2e4}
    remove, accept, calls, gain_calls, accepted = _table(chi2)
    kept, dropped, last = backward_eliminate(["viscoelastic", "detector_nonlinearity"],
                                             [7.24, 9.88], MIN_GAIN, remove, accept)
    assert kept == [0, 1] and dropped == [] and accepted == []
    assert calls == [(1, (0, 1)), (0, (0, 1))]
    assert last[1].chi2_rise == pytest.approx(4700.0)
    assert last[0].chi2_rise == pytest.approx(6700.0)


def test_backward_checks_again_after_a_drop():
    """A cause kept against the old final model (the third) is checked again once another
    is dropped: without the second cause it no longer raises chi2 (both modelled one
    feature), so it goes too; the held-out gain drops a cause whose rise is significant."""
    f = frozenset
    chi2 = {f({0, 1, 2}): 100.0, f({0, 1}): 150.0, f({0, 2}): 101.0, f({1, 2}): 900.0,
            f({0}): 105.0, f({2}): 880.0, f({1}): 890.0, f(): 160.0}
    remove, accept, calls, gain_calls, accepted = _table(chi2, {(0, (0,)): 0.01})
    kept, dropped, last = backward_eliminate(["a", "b", "c"], [10.0, 10.0, 10.0], MIN_GAIN,
                                             remove, accept)
    # after the drop the last named is checked first again
    assert calls == [(2, (0, 1, 2)), (1, (0, 1, 2)), (2, (0, 2)), (0, (0,))]
    assert [d.cause for d in dropped] == ["b", "c", "a"] and kept == []
    assert "held-out gain +0.010" in dropped[2].reason and dropped[2].gain == 0.01
    assert last == {}


def test_backward_needs_a_threshold_per_cause():
    with pytest.raises(ValueError, match="thresholds"):
        backward_eliminate(["a", "b"], [1.0], MIN_GAIN, lambda i, k: (0.0, lambda: 0.0, 1.0),
                           lambda i: None)


# ---------------------------------------------------------------------- end to end
#: the session-6 demo's hidden draw (``scripts/demo.py``, make demo at df1a5fa): a strong
#: long-range damping (1.1e-7 N s/m decaying over 2.3 nm) at two free amplitudes, 4 rest gaps
#: each, 40 periods, 200 samples/period, 1 % noise. Diagnosed before the backward check:
#: damping (gain 0.53), then adhesion_hysteresis (neck coefficient -3.6e-16 in the final
#: model) and higher_mode
DEMO = SeriesCase.from_dict({
    "causes": ["long_range_damping"], "quality_factor": 394.166929104713,
    "free_amplitude_m": 1.4087542204527583e-08,
    "setpoints": [0.9065839084461857, 0.7604130760670399, 0.587176043063677,
                  0.45662425362195025, 0.8461980678547725, 0.6839990978487301,
                  0.5156445203989111, 0.38942962112807267],
    "settle_offsets": [0.07687404156297395, 0.5235108936767144, 0.6408700982863361,
                       0.23438764280299162, 0.9779113283108654, 0.6648101364379003,
                       0.6448176812134976, 0.3050463245785866],
    "tip_radius_m": 1.3189781887432391e-08, "hamaker_j": 1.0845086326583164e-19,
    "reduced_modulus_pa": 1798300621.0599926, "a0_m": 2.1398791075222758e-10,
    "effects": {"long_range_damping": {"coefficient_ns_per_m": 1.10309445855763e-07,
                                       "decay_length_m": 2.2999999188711433e-09}},
    "seed": 1602717219,
    "free_amplitudes_m": [1.4087542204527583e-08] * 4 + [3.9145113094198114e-08] * 4})


def _added_coefficients(dg: Diagnoser) -> dict[str, list[float]]:
    """Per kept cause, the final model's force coefficients of the columns its step added
    (empty for a cause that adds no column: a mode, a detector map, an exponent)."""
    spec, coef = dg.extended_.spec, dg.extended_.coef
    keys = spec.term_keys()
    out = {}
    seen = {"vdw", "contact"}
    for s in dg.causes_:
        c = next(c for c in s.candidates if c.cause == s.cause)
        new = [k for k in c.model.spec.term_keys() if k not in seen]
        seen |= set(new)
        out[s.cause] = [float(coef[3 + keys.index(k)]) for k in new if k in keys]
    return out


@pytest.mark.slow
def test_demo_damping_keeps_no_cause_with_a_zero_coefficient(tmp_path):
    """The demo's draw (~100 s CPU): named long_range_damping first, and every cause kept has
    a column that matters (before the check: a neck at -3.6e-16); the report lists the
    dropped ones with their chi2 rise below their threshold."""
    folder = simulate_series(DEMO, tmp_path / "measured", samples_per_period=200,
                             n_periods=40.0, noise_level=0.01)
    dg = Diagnoser(max_causes=3).fit(read_experiment(series_files(folder)))
    named = [s.cause for s in dg.causes_]
    msg = (f"kept {named}, dropped {dg.dropped_causes_}; "
           f"{dg.extended_.equation()}")
    assert dg.cause_ == "long_range_damping" == named[0], msg
    scale = max(abs(float(c)) for c in dg.extended_.coef[3:3 + dg.extended_.spec.n_force])
    for cause, coefs in _added_coefficients(dg).items():
        assert all(abs(c) > 1e-6 * scale for c in coefs), (cause, coefs, msg)
    for s in dg.causes_[1:]:
        assert s.removal is not None and s.removal.kept, msg
        assert s.removal.chi2_rise > s.removal.threshold, msg
    for d in dg.dropped_causes_:
        assert not d.kept and d.cause not in named, msg
    assert dg.gain_ > 0.3, msg
    rec = report_record(dg, input_path=folder / "amplitude-0.h5", row=None, figures=[],
                        runtime_s=0.0)
    assert [c["cause"] for c in rec["causes"]] == named
    assert [d["cause"] for d in rec["dropped_causes"]] == [d.cause for d in dg.dropped_causes_]
    if dg.dropped_causes_:
        assert "Dropped by the backward check" in report_markdown(rec, {})
    assert rec["extended"]["chi2"] == pytest.approx(dg.extended_chi2_)


@pytest.mark.slow
def test_two_real_causes_both_stay_named(make_series):
    """A long-range damping and a detector nonlinearity at once (4 set-points x 20 periods,
    dev seed 2): two causes are named step by step, the detector and a dissipative one, and
    the backward check keeps both, each raising chi2 far above its threshold when removed
    from the final model and adding held-out gain there. Measured where it was written:
    damping + detector, rises 101 / 28,437 (thresholds 9.88), gains 0.87 / 0.89. On the AMD
    EPYC / OpenBLAS-Haswell machine (80fd5d1 and after) the dissipative step names the
    visco-elastic loss instead (drop 363 against damping's 148, then the detector; rises 96 /
    41,634, gains 0.87 / 0.59): on 4 set-points x 20 periods the two losses are the
    dissipative tie measured in docs/benchmarks.md, which the series tests pin down on their
    own draws (test_dissipative_causes.py); what this test checks is the backward check."""
    path, _ = make_series("long_range_damping+detector_nonlinearity", 2)
    dg = Diagnoser(hypotheses=[Viscoelastic(), DetectorNonlinearity(), LongRangeDamping()])
    dg.fit(read_trace(path))
    named = [s.cause for s in dg.causes_]
    msg = f"kept {named}, dropped {dg.dropped_causes_}"
    assert len(named) == 2 and "detector_nonlinearity" in named, msg
    assert set(named) & {"long_range_damping", "viscoelastic"}, msg
    assert dg.dropped_causes_ == [], msg
    for s in dg.causes_:
        assert s.removal is not None and s.removal.kept, msg
        assert s.removal.chi2_rise > 3 * s.removal.threshold, msg
        assert s.removal.gain > MIN_GAIN, msg
    assert np.isfinite(dg.gain_) and dg.gain_ > dg.causes_[0].gain


@pytest.mark.slow
def test_a_real_cause_is_kept_when_the_rest_of_the_model_is_wrong(make_series):
    """Damping + detector dev draw [3, 78] (4 set-points x 20 periods) diagnosed WITHOUT the
    damping hypothesis, so the final model carries a wrong dissipative cause (visco-elastic):
    the real detector's removal raises chi2 by ~40,000 (threshold 9.88). The held-out gain of
    the detector in that final model is fragile: -0.25 on 773f2bc (the detector dropped by
    it, visco named alone), +0.69 on 95d533f (its wider tie margin re-measures one more
    first-step candidate), and under pytest on 95d533f the detector was named alone; whatever
    it is, the detector stays, and a conflict is said in a note and a warning. (The rule
    itself: the fast tests above.)"""
    path, case = make_series("long_range_damping+detector_nonlinearity", 3)
    dg = Diagnoser(hypotheses=[Viscoelastic(), DetectorNonlinearity()])
    dg.fit(read_trace(path))
    named = [s.cause for s in dg.causes_]
    msg = f"kept {named}, dropped {dg.dropped_causes_}"
    assert "detector_nonlinearity" in named, msg
    assert not any(d.cause == "detector_nonlinearity" for d in dg.dropped_causes_), msg
    det = next(s for s in dg.causes_ if s.cause == "detector_nonlinearity")
    if det.removal is not None:              # two causes named: the backward check ran
        assert det.removal.chi2_rise > 100 * det.removal.threshold, msg
        if not det.removal.gain > MIN_GAIN:  # the conflict: said, not hidden
            assert "another of its causes" in det.removal.note
            assert any("detector_nonlinearity kept although" in w for w in dg.warnings_)
