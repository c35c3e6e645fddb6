"""Joint fit of one law across curves of one tip at several free amplitudes: the block
Jacobian against a plain one, recovery of a shared law, the joint diagnosis and its
leave-one-curve-out gain, the lever check and the sets of a folder."""

from __future__ import annotations

import math

import numpy as np
import pytest

from afmlearn.curves import Curve, CurveLaw, SlowFlowModel
from afmlearn.curves.analyze_group import split_sets
from afmlearn.curves.group import GroupFitter, check_same_lever
from afmlearn.curves.group_diagnose import GroupDiagnoser
from afmlearn.curves.hypotheses import EXTENSIONS
from afmlearn.curves.transfer import rescale_law

K_N, Q, F0 = 2.7, 150.0, 70e3
L1 = 20e-9
#: one SI law with long-range damping, written in units of L1 = 20 nm
DAMPED = CurveLaw(a0=0.3e-9 / L1, vdw=2e-6, stiffness=40.0, damping=2e-3, decay_length=0.2,
                  radius=10e-9 / L1)
DAMPING = next(h for h in EXTENSIONS if h.cause == "long_range_damping")
VISCO = next(h for h in EXTENSIONS if h.cause == "viscoelastic")


def synthetic(law1: CurveLaw, length_m: float, offset: float, *, seed: int | None = None,
              n: int = 200, k_n: float = K_N) -> Curve:
    """An approach--retract curve of free amplitude ``length_m`` made by the model, with 1 %
    amplitude and 0.5 deg phase noise when ``seed`` is given."""
    law = rescale_law(law1, L1 / length_m)
    tau = 2 * math.pi * 6 * np.arange(2 * n)
    gap = np.concatenate([np.linspace(2.0, 0.3, n), np.linspace(0.3, 2.0, n)])
    model = SlowFlowModel(quality_factor=Q, omega=1.0, drive=1.0 / Q, step=4 * math.pi)
    amp, phi = model.predict(law, tau, gap)
    if seed is not None:
        rng = np.random.default_rng(seed)
        amp = amp + 0.01 * rng.standard_normal(amp.size)
        phi = phi + math.radians(0.5) * rng.standard_normal(phi.size)
    return Curve(tau=tau, amplitude=amp, phase=phi, z_piezo=gap + offset,
                 segment=np.repeat(np.array([0, 1], dtype=np.int8), n), quality_factor=Q,
                 spring_constant_n_per_m=k_n, resonance_frequency_hz=F0, length_m=length_m,
                 drive_frequency_hz=F0)


def true_start(fitter_law: CurveLaw, curves: list[Curve], offsets: list[float]) -> dict:
    return {"law": {k: getattr(fitter_law, k) for k in ("vdw", "stiffness", "damping",
                                                         "decay_length")},
            "curves": [{"offset": o, "omega": 1.0} for o in offsets]}


def test_block_jacobian_equals_the_plain_one():
    """A nuisance column moves only its own curve: the block Jacobian equals the dense
    finite-difference Jacobian of the concatenated residual."""
    curves = [synthetic(DAMPED, L, 1.0, n=60) for L in (15e-9, 30e-9)]
    f = GroupFitter(hypothesis=DAMPING, max_nfev=1, rescales=((1.0, 1.0),),
                    start={"law": {"vdw": 1.5e-6, "stiffness": 30.0, "damping": 1e-3,
                                   "decay_length": 0.3},
                           "curves": [{"offset": 1.02, "omega": 1.0001}] * 2}).fit(curves)
    x = f.x_.copy()
    jac = f._jacobian(x)
    r0 = f._residual(x)
    plain = np.zeros_like(jac)
    for j in range(x.size):
        y = x.copy()
        h = 1e-4 * max(1.0, abs(x[j]))
        y[j] = x[j] + h if x[j] + h <= f._hi[j] else x[j] - h
        plain[:, j] = (f._residual(y) - r0) / (y[j] - x[j])
    np.testing.assert_allclose(jac, plain, rtol=1e-10, atol=1e-10)
    # the nuisance of curve 0 does not move curve 1's residual
    m0 = curves[0].segment.tolist().count(0) * 2
    assert np.all(jac[m0:, 0] == 0.0) and np.any(jac[:m0, 0] != 0.0)


def _fit_from_perturbed_start(curves):
    """The true law in the group's unit and the joint damping fit from a start 50 % off it
    (every curve's surface offset 3 % off)."""
    n = len(curves)
    probe = GroupFitter(hypothesis=DAMPING, max_nfev=1,
                        start=true_start(DAMPED, curves, [1.0] * n)).fit(curves)
    truth = rescale_law(DAMPED, L1 / probe.length_m_)
    start = {"law": {"vdw": truth.vdw * 1.5, "stiffness": truth.stiffness * 0.6,
                     "damping": truth.damping * 0.5, "decay_length": truth.decay_length * 1.4},
             "curves": [{"offset": 1.03, "omega": 1.0}] * n}
    fit = GroupFitter(hypothesis=DAMPING, start=start, rescales=((1.0, 1.0),),
                      max_nfev=30).fit(curves)
    return truth, fit


def test_joint_fit_recovers_the_shared_law_from_a_perturbed_start_fast():
    """The fast check of the recovery below: two noiseless curves at 15 and 40 nm of one damped
    tip (80 points per branch); the joint law returns to the truth from a start 50 % off
    (measured: attraction and stiffness within 0.2 %, the near damping 2 %, its decay 3 %, the
    loss (their product) 1 %), the far term stays off, each surface to 1e-3."""
    curves = [synthetic(DAMPED, L, 1.0, n=80) for L in (15e-9, 40e-9)]
    truth, fit = _fit_from_perturbed_start(curves)
    assert fit.law_.vdw == pytest.approx(truth.vdw, rel=0.01)
    assert fit.law_.stiffness == pytest.approx(truth.stiffness, rel=0.01)
    assert fit.law_.damping * fit.law_.decay_length == pytest.approx(
        truth.damping * truth.decay_length, rel=0.03)
    assert fit.law_.damping == pytest.approx(truth.damping, rel=0.06)
    assert fit.law_.decay_length == pytest.approx(truth.decay_length, rel=0.06)
    assert fit.law_.far_damping < 0.01 * fit.law_.damping
    for cv in fit.values_["curves"]:
        assert cv["offset"] == pytest.approx(1.0, abs=1e-3)
    # the start's chi2 is far above; the fit's is well below one per residual
    assert fit.chi2_ / fit.n_fit_ < 0.1


@pytest.mark.slow
def test_joint_fit_recovers_the_shared_law_from_a_perturbed_start():
    """Three noisy curves at 15, 25 and 40 nm of one damped tip: the joint law (group unit)
    returns to the truth from a start 50 % off, each curve's surface position to 1 %."""
    lengths = (15e-9, 25e-9, 40e-9)
    curves = [synthetic(DAMPED, L, 1.0, seed=i, n=150) for i, L in enumerate(lengths)]
    truth, fit = _fit_from_perturbed_start(curves)
    # the fit reaches the truth's basin (its chi2 at or below the true law's)
    x_true = fit._encode({"law": {"vdw": truth.vdw, "stiffness": truth.stiffness,
                                  "damping": truth.damping,
                                  "decay_length": truth.decay_length, "far_damping": 1e-8},
                          "curves": [{"offset": 1.0, "omega": 1.0}] * 3})
    assert fit.chi2_ <= 1.01 * fit._cost(x_true)
    # the damping hypothesis has a near and a far term (4 parameters, be83a6b): the noise
    # trades the near coefficient against its decay (measured: 0.00235 / 0.144 against 0.002 /
    # 0.162, chi2 1277 below the truth's 1284); their product, the loss, is tight, the far
    # term stays off
    assert fit.law_.damping * fit.law_.decay_length == pytest.approx(
        truth.damping * truth.decay_length, rel=0.1)
    assert fit.law_.damping == pytest.approx(truth.damping, rel=0.25)
    assert fit.law_.decay_length == pytest.approx(truth.decay_length, rel=0.15)
    assert fit.law_.far_damping < 0.01 * fit.law_.damping
    for cv in fit.values_["curves"]:
        assert cv["offset"] == pytest.approx(1.0, abs=0.01)
    # at the noise level: chi2 per residual near 1
    assert fit.chi2_ / fit.n_fit_ < 1.5


def test_joint_diagnosis_names_damping_with_a_positive_left_out_gain():
    """Damped curves at 15 and 35 nm: the joint diagnosis (damping vs visco) names damping and
    the law fitted on one curve predicts the other better than the baseline does."""
    curves = [synthetic(DAMPED, L, 1.0, seed=10 + i, n=150)
              for i, L in enumerate((15e-9, 35e-9))]
    d = GroupDiagnoser(hypotheses=(VISCO, DAMPING), max_evaluations=1000).fit(curves)
    assert d.cause_ == "long_range_damping"
    assert d.gain_ > 0.0
    assert len(d.loo_["none"]) == 2 and len(d.loo_["long_range_damping"]) == 2
    assert d.n_evaluations_ <= 1000 + 50  # the final residuals are always computed
    rep = d.report()
    for key in ("cause", "confidence", "baseline", "extended", "gain", "candidates", "causes",
                "figures", "group"):
        assert key in rep
    assert rep["group"]["n_curves"] == 2


def test_curves_of_different_levers_are_refused():
    a = synthetic(DAMPED, 15e-9, 1.0, n=30)
    b = synthetic(DAMPED, 25e-9, 1.0, n=30, k_n=2 * K_N)
    with pytest.raises(ValueError, match="spring_constant_n_per_m"):
        check_same_lever([a, b])
    with pytest.raises(ValueError, match="spring_constant_n_per_m"):
        GroupFitter().fit([a, b])


def test_sets_span_the_free_amplitudes():
    lengths = [30.0, 10.0, 50.0, 20.0, 60.0, 40.0, 70.0]
    sets = split_sets(lengths, 3)
    assert len(sets) == 2
    for s in sets:
        vals = sorted(lengths[i] for i in s)
        assert vals[0] <= 20.0 and vals[-1] >= 50.0   # low and high amplitudes in every set
    assert len({i for s in sets for i in s}) == 6
    with pytest.raises(ValueError, match="group_size"):
        split_sets(lengths, 0)


def test_a_start_from_another_set_of_curves_is_the_same_si_law():
    """A subset of the curves has another length unit: the full fit's values, used as a
    start there, give the same per-curve residuals (the law is rescaled, not reread)."""
    curves = [synthetic(DAMPED, L, 1.0, seed=20 + i, n=60)
              for i, L in enumerate((15e-9, 25e-9, 40e-9))]
    start = {"law": {"vdw": 1.5e-6, "stiffness": 30.0, "damping": 1.5e-3,
                     "decay_length": 0.2}, "curves": [{"offset": 1.0, "omega": 1.0}] * 3}
    full = GroupFitter(hypothesis=DAMPING, max_nfev=2, rescales=((1.0, 1.0),),
                       start=start).fit(curves)
    sub = {"law": full.values_["law"], "length_m": full.length_m_,
           "curves": full.values_["curves"][1:]}
    part = GroupFitter(hypothesis=DAMPING, max_nfev=1, max_evaluations=3,
                       rescales=((1.0, 1.0),), start=sub).fit(curves[1:])
    assert part.length_m_ != pytest.approx(full.length_m_, rel=1e-3)
    # the same SI law up to rounding, which the adaptive steps feel (measured 7e-10 and 2e-7
    # relative for two far-term starts); a law reread in the wrong unit is off by orders
    assert part.chi2_ == pytest.approx(sum(full.chi2_curves_[1:]), rel=1e-6)


def test_a_flat_curve_keeps_its_surface_out_of_reach():
    """A curve that never meets the surface (amplitude stays free): the surface guess and its
    bounds lie beyond the closest rest gap of one free amplitude (no forced fake contact)."""
    from afmlearn.curves.group import offset_guess

    flat = synthetic(DAMPED.replace(vdw=0.0, damping=0.0), 20e-9, 1.0, n=40)
    flat = Curve(tau=flat.tau, amplitude=np.ones_like(flat.amplitude), phase=flat.phase,
                 z_piezo=flat.z_piezo, segment=flat.segment, quality_factor=Q,
                 spring_constant_n_per_m=K_N, resonance_frequency_hz=F0, length_m=20e-9,
                 drive_frequency_hz=F0)
    closest = float(np.min(flat.z_piezo))
    assert offset_guess(flat) + 0.6 < closest - 0.8
    touching = synthetic(DAMPED, 20e-9, 1.0, n=60)
    assert offset_guess(touching) == pytest.approx(1.0, abs=0.1)


def test_starts_from_singles_leave_out_the_single_curve_free_scale():
    """A single-curve damping fit carries the free-amplitude scale, a nuisance of that curve
    the joint fit holds at 1: the joint starts hold the law only, rescaled to the group unit
    (it raised AttributeError, CurveLaw has no free_scale: F, session 8)."""
    from types import SimpleNamespace

    from afmlearn.curves.group import group_length
    from afmlearn.curves.group_diagnose import starts_from_singles

    curves = [synthetic(DAMPED, L, 1.0, n=20) for L in (15e-9, 40e-9)]
    diags = []
    for c in curves:
        law = rescale_law(DAMPED, L1 / c.length_m).replace(far_damping=3e-4, far_decay_length=5.0)
        values = {"offset": 1.0, "omega": 1.0, "free_scale": 1.1}
        values.update({k: getattr(law, k) for k in ("vdw", "stiffness", "damping",
                                                    "decay_length", "far_damping",
                                                    "far_decay_length")})
        fit = SimpleNamespace(values_=values, law_=law)
        base = SimpleNamespace(values_={k: values[k] for k in ("offset", "omega", "vdw",
                                                               "stiffness")}, law_=law)
        diags.append(SimpleNamespace(curve_=c, fits_={"long_range_damping": fit},
                                     baseline_=base))
    starts = starts_from_singles(diags)
    length = group_length(curves)
    for s in starts["long_range_damping"]:
        assert "free_scale" not in s["law"]
        assert s["curves"] == [{"offset": 1.0, "omega": 1.0}] * 2
        # the same SI law in the group unit: the near decay is 0.2 x 20 nm
        assert s["law"]["decay_length"] * length == pytest.approx(0.2 * L1, rel=1e-12)
        assert s["law"]["damping"] == pytest.approx(DAMPED.damping, rel=1e-12)


def _tail_curve(law: CurveLaw, length_m: float, n: int = 60) -> tuple[Curve, float]:
    """A noiseless curve whose ramp starts within reach of the electrostatic tail of ``law``
    (units of ``length_m``, the true free amplitude), normalised as a recording is: by the
    amplitude at the ramp's far end, which is below the free one. Returns the curve and the
    true free-amplitude scale (free / far-end amplitude)."""
    tau = 2 * math.pi * 6 * np.arange(2 * n)
    gap = np.concatenate([np.linspace(1.25, 0.3, n), np.linspace(0.3, 1.25, n)])
    model = SlowFlowModel(quality_factor=Q, omega=1.0, drive=1.0 / Q, step=4 * math.pi)
    amp, phi = model.predict(law, tau, gap)
    seg = np.repeat(np.array([0, 1], dtype=np.int8), n)
    raw = Curve(tau=tau, amplitude=amp, phase=phi, z_piezo=gap + 1.0, segment=seg,
                quality_factor=Q, spring_constant_n_per_m=K_N, resonance_frequency_hz=F0,
                length_m=length_m, drive_frequency_hz=F0)
    far = float(np.median(amp[raw.far()]))
    return Curve(tau=tau, amplitude=amp / far, phase=phi, z_piezo=(gap + 1.0) / far,
                 segment=seg, quality_factor=Q, spring_constant_n_per_m=K_N,
                 resonance_frequency_hz=F0, length_m=length_m * far,
                 drive_frequency_hz=F0), 1.0 / far


def test_a_ramp_started_within_reach_of_the_tail_needs_the_free_scale():
    """An 8 nm curve whose ramp starts 10 nm out, within reach of a charged tip's tail: the
    far end is 12 % below free and 30 deg off (session 8: 16 %, 35 deg). With the true law
    held fixed, the fitted free-amplitude scale is the true one (free / far-end amplitude) and
    the curve is reproduced; held at 1, no surface position and drive frequency can."""
    length = 8e-9
    law = CurveLaw(a0=0.3e-9 / length, vdw=2e-6, stiffness=40.0, electrostatic=5e-3,
                   radius=10e-9 / length)
    curve, scale = _tail_curve(law, length)
    assert 1.1 < scale < 1.2 and abs(curve.free_phase - math.pi / 2) > math.radians(20)
    held = GroupFitter(fixed_law=(law, length)).fit([curve])
    free = GroupFitter(fixed_law=(law, length), free_scale=True).fit([curve])
    assert free.values_["curves"][0]["free_scale"] == pytest.approx(scale, rel=1e-4)
    assert free.values_["curves"][0]["offset"] * curve.length_m == pytest.approx(
        1.0 * length, rel=1e-4)
    # noiseless: the model's own residual (floor sigma) against 1e5 held at 1 (measured
    # 2e-4 and 3.6e5)
    assert free.chi2_ < 1e-2 < 1e3 < held.chi2_
    assert "free_scale" not in held.values_["curves"][0]
    # the start of a fit: from the recorded far end (scale 1, drive frequency from the far
    # lag), one step of the linear lever's far-end match lands near the truth (measured:
    # scale 1.146 against 1.138, drive frequency 1.0005 against 1, from 1.0019)
    x0 = free._encode({"law": {}, "curves": [{"offset": length / curve.length_m}]})
    assert x0[2] == 1.0 and abs(x0[1] - 1.0) > 1.5e-3
    x1 = free._far_start(x0)
    assert x1[2] == pytest.approx(scale, rel=0.02) and abs(x1[1] - 1.0) < 6e-4


def test_the_neck_is_tested_on_the_retraction_not_on_left_out_curves():
    """A neck shows where the tip leaves the surface: the joint diagnosis names it by its
    evidence and the retraction gain of the joint fit (not fitted) and leaves no curve out for
    it (session 8: left-out curves that barely touch refuted 2 of 10 neck groups); a
    non-hysteretic candidate above the threshold is still tested on left-out curves."""
    neck = next(h for h in EXTENSIONS if h.cause == "adhesion_hysteresis")
    assert neck.hysteretic and not VISCO.hysteretic
    curves = [synthetic(DAMPED.replace(damping=0.0, neck=0.02), L, 1.0, seed=30 + i, n=100)
              for i, L in enumerate((15e-9, 35e-9))]
    d = GroupDiagnoser(hypotheses=(VISCO, neck), max_evaluations=800).fit(curves)
    assert d.cause_ == "adhesion_hysteresis"
    named = d.candidates_[0]
    assert named["gain_loo"] is None and "adhesion_hysteresis" not in d.loo_
    assert named["gain"] == named["gain_retraction"] > 0.05
    visco = next(c for c in d.candidates_ if c["cause"] == "viscoelastic")
    assert (visco["gain_loo"] is not None) == (visco["evidence"] > d.threshold)


def test_the_surface_of_a_curve_held_off_by_the_tail_is_found_below_the_amplitude_guess():
    """A strong tail at 6.7 nm free amplitude (the bench's 8 nm electrostatic member): the
    amplitude falls to 4 % without the tip reaching the surface, so the amplitude-based
    surface guess is one free amplitude too far out (measured 2.03 against 1.0). With free
    scales the surface bound reaches down to the tip's closest turning point - 0.6 and the
    scan goes there: the true law held fixed reproduces the curve (measured chi2 2e-14); the
    old +-0.3 scan (free scales off) stays near the guess (chi2 6e7)."""
    from afmlearn.curves.group import offset_guess

    length = 6.7e-9
    law = CurveLaw(a0=0.3e-9 / length, vdw=3e-4, stiffness=4.5, electrostatic=0.05,
                   radius=10e-9 / length)
    n = 80
    tau = 2 * math.pi * 6 * np.arange(2 * n)
    gap = np.concatenate([np.linspace(2.7, 0.43, n), np.linspace(0.43, 2.7, n)])
    model = SlowFlowModel(quality_factor=Q, omega=1.0, drive=1.0 / Q, step=4 * math.pi)
    amp, phi = model.predict(law, tau, gap)
    curve = Curve(tau=tau, amplitude=amp, phase=phi, z_piezo=gap + 1.0,
                  segment=np.repeat(np.array([0, 1], dtype=np.int8), n), quality_factor=Q,
                  spring_constant_n_per_m=K_N, resonance_frequency_hz=F0, length_m=length,
                  drive_frequency_hz=F0)
    assert offset_guess(curve) > 1.9 and amp.min() < 0.05
    wide = GroupFitter(fixed_law=(law, length), free_scale=True).fit([curve])
    assert wide.values_["curves"][0]["offset"] == pytest.approx(1.0, abs=1e-3)
    assert wide.chi2_ < 1e-2
    old = GroupFitter(fixed_law=(law, length)).fit([curve])
    assert old.values_["curves"][0]["offset"] > 1.5 and old.chi2_ > 1e3
