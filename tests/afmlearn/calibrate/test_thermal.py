"""Thermal calibration: windows, Welch spectra, the exact oscillator generator and the fit."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.signal import welch

from afmlearn.calibrate import (
    GammaLikelihood,
    Hann,
    PointSample,
    PowerSpectrum,
    Rectangular,
    ThermalCorrection,
    ThermalFit,
    WindowResponse,
    welch_spectrum,
)
from afmlearn.calibrate.sho import BOLTZMANN_J_PER_K, dc_level, mean_square, sho_psd
from afmlearn.calibrate.synthetic import thermal_time_series
from afmlearn.calibrate.windows import bin_correlation, power_response

TRUTH = dict(resonance_frequency_hz=100e3, quality_factor=150.0, spring_constant_n_per_m=2.0)
FS = 1e6
T = 300.0


def test_sho_mean_square_is_the_integral_and_inverts_dc_level():
    f0, q, dc = 50e3, 80.0, 3e-27
    numeric = sum(quad(lambda f: sho_psd(f, f0, q, dc), a, b, limit=500)[0]
                  for a, b in ((0, f0), (f0, 2 * f0), (2 * f0, np.inf)))
    assert mean_square(f0, q, dc) == pytest.approx(numeric, rel=1e-6)
    level = dc_level(f0, q, 2.5, T, 0.817)
    assert mean_square(f0, q, level) == pytest.approx(0.817 * BOLTZMANN_J_PER_K * T / 2.5)


def test_window_power_response_integrates_to_one_and_matches_analytic_correlation():
    offsets = np.arange(-200 * 8, 200 * 8 + 1) / 8
    for window in (Rectangular(), Hann()):
        w = power_response(window, 512, offsets)
        assert np.sum(w) / 8 == pytest.approx(1.0, abs=2e-3)  # Parseval, tails beyond 200 bins
        assert w.argmax() == offsets.size // 2
    rho = bin_correlation(Hann(), 1024)
    assert rho[1] == pytest.approx(4 / 9) and rho[2] == pytest.approx(1 / 36)
    assert max(bin_correlation(Rectangular(), 1024)[1:]) < 1e-20


def test_welch_matches_scipy_and_its_scatter_matches_the_equivalent_averages():
    rng = np.random.default_rng(3)
    x = rng.normal(0.0, 1e-10, 2048 * 200)
    spec = welch_spectrum(x, FS, segment_length=2048, window=Hann(), overlap=0.5)
    f_ref, p_ref = welch(x, FS, window="hann", nperseg=2048, noverlap=1024, detrend="constant")
    np.testing.assert_allclose(spec.frequency_hz, f_ref)
    np.testing.assert_allclose(spec.psd_m2_per_hz[1:-1], p_ref[1:-1], rtol=1e-10)
    # white noise: every bin's relative variance is 1 / n_averages (Gamma with that shape);
    # ~1000 bins, correlated in pairs: the variance estimate is good to ~6 %
    rel = spec.psd_m2_per_hz[5:-5] / (2 * 1e-20 / FS) - 1.0
    assert np.var(rel) * spec.n_averages == pytest.approx(1.0, abs=0.2)
    assert 200 < spec.n_averages < 2 * 200 - 1  # overlap adds information, less than 2x


def test_generator_variance_is_equipartition():
    rng = np.random.default_rng(0)
    x = thermal_time_series(400_000, sample_rate_hz=FS, temperature_k=T, rng=rng, **TRUTH)
    target = BOLTZMANN_J_PER_K * T / TRUTH["spring_constant_n_per_m"]
    # ~400 000 / (Q / (pi f0) * fs) ~ 800 correlation times: 5 % is > 3 sigma
    assert np.var(x) == pytest.approx(target, rel=0.05)


def _spectrum(seed: int, *, segment_length: int, window, n_segments: int) -> PowerSpectrum:
    rng = np.random.default_rng(seed)
    x = thermal_time_series(segment_length * n_segments, sample_rate_hz=FS, temperature_k=T,
                            background_m2_per_hz=2e-27, rng=rng, **TRUTH)
    return welch_spectrum(x, FS, segment_length=segment_length, window=window, overlap=0.5)


def _fit(spec: PowerSpectrum, response, noise=None) -> ThermalFit:
    return ThermalFit(temperature_k=T, correction=ThermalCorrection.point_mass(),
                      response=response, noise=noise,
                      fit_range_hz=(60e3, 140e3)).fit(spec)


@pytest.mark.parametrize("seed", [1, 2])
def test_fit_as_measured_recovers_truth_within_its_intervals(seed):
    # 1024-sample Hann segments: bin width 977 Hz, line width f0/Q = 667 Hz (< 1 bin)
    spec = _spectrum(seed, segment_length=1024, window=Hann(), n_segments=300)
    fit = _fit(spec, WindowResponse(Hann(), 1024))
    for name, value in TRUTH.items():
        lo, hi = fit.intervals_[name]
        assert lo <= value <= hi, (name, lo, value, hi)
    assert fit.reduced_deviance_ == pytest.approx(1.0, abs=0.15)
    # intervals are informative: Q to better than 15 %, f0 to 0.1 %
    q_lo, q_hi = fit.intervals_["quality_factor"]
    assert (q_hi - q_lo) / TRUTH["quality_factor"] < 0.3
    assert fit.resonance_frequency_hz_ == pytest.approx(TRUTH["resonance_frequency_hz"],
                                                        rel=1e-3)


def test_ignoring_the_window_broadens_the_peak_and_lowers_q():
    """The issue's hypothesis, measured: with a rectangular window (leakage ~ sinc^2) and a
    line 2.7 bins wide, a point-sampled model underestimates Q by ~10 %, outside its own
    interval, while its deviance looks fine; the window's bin response removes the bias."""
    spec = _spectrum(5, segment_length=4096, window=Rectangular(), n_segments=300)
    naive = _fit(spec, PointSample())
    modelled = _fit(spec, WindowResponse(Rectangular(), 4096))
    q = TRUTH["quality_factor"]
    assert naive.intervals_["quality_factor"][1] < q  # biased low, interval misses the truth
    assert naive.reduced_deviance_ < 1.1  # ... and the goodness of fit does not show it
    lo, hi = modelled.intervals_["quality_factor"]
    assert lo <= q <= hi
    assert modelled.quality_factor_ > 1.05 * naive.quality_factor_


def test_fit_rejects_bad_settings():
    spec = _spectrum(7, segment_length=256, window=Hann(), n_segments=20)
    with pytest.raises(ValueError, match="temperature_k"):
        ThermalFit(temperature_k=-1.0).fit(spec)
    with pytest.raises(ValueError, match="fit_range_hz"):
        ThermalFit(temperature_k=T, fit_range_hz=(5e3, 1e3)).fit(spec)
    with pytest.raises(ValueError, match="spectrum"):
        ThermalFit(temperature_k=T).fit(np.ones(10))
    assert math.isfinite(ThermalFit(temperature_k=T, fit_range_hz=(60e3, 140e3)).fit(
        spec).quality_factor_)


def test_gamma_likelihood_is_minimal_at_the_observed_value():
    noise = GammaLikelihood()
    obs = np.array([2.0, 3.0])
    values = [noise.objective(obs, obs * s, 10) for s in (0.9, 1.0, 1.1)]
    assert values[1] < values[0] and values[1] < values[2]


def test_calibrate_file_from_a_raw_time_series_npz(tmp_path):
    """The documented path for a raw thermal time series: NPZ with ``deflection_m`` and
    ``sample_rate_hz`` -> Welch (Hann, stated N) -> fit -> calibration.json."""
    from afmlearn.calibrate.report import calibrate_file

    rng = np.random.default_rng(11)
    x = thermal_time_series(1024 * 300, sample_rate_hz=FS, temperature_k=T,
                            background_m2_per_hz=2e-27, rng=rng, **TRUTH)
    np.savez(tmp_path / "thermal.npz", deflection_m=x, sample_rate_hz=FS)
    fit, result, spectrum = calibrate_file(
        tmp_path / "thermal.npz", tmp_path / "out", read_options={"segment_length": 1024},
        temperature_k=T, correction=ThermalCorrection.point_mass(), fit_range_hz=(60e3, 140e3),
        compare=False)
    assert spectrum.window == Hann() and spectrum.segment_length == 1024
    assert result["window"]["stated_by_file"]
    saved = (tmp_path / "out" / "calibration.json").read_text()
    assert '"spring_constant_n_per_m_interval"' in saved
    for name, value in TRUTH.items():
        lo, hi = result[f"{name}_interval"]
        assert lo <= value <= hi, (name, lo, value, hi)


def _gamma_spectrum(psd, f, n_avg, seed):
    rng = np.random.default_rng(seed)
    return PowerSpectrum(f, psd * rng.gamma(n_avg, 1.0 / n_avg, f.size), n_averages=n_avg)


def test_second_peak_check_finds_a_hidden_neighbour_and_leaves_a_single_line_alone():
    from afmlearn.calibrate.lineshape import second_peak_check

    f = np.arange(2000) * 40.0 + 140e3
    f0, q, k, b = 180e3, 450.0, 9.0, 1e-26
    main = sho_psd(f, f0, q, dc_level(f0, q, k, T, 1.0)) + b
    extra = sho_psd(f, 178.9e3, 230.0, dc_level(178.9e3, 230.0, 120.0, T, 1.0))
    for psd, hidden in ((main + extra, True), (main, False)):
        spec = _gamma_spectrum(psd, f, 1000, seed=4)
        single = ThermalFit(temperature_k=T, correction=ThermalCorrection.point_mass(),
                            response=PointSample()).fit(spec)
        check = second_peak_check(spec, single)
        if hidden:  # the single line is rejected and biased; two lines recover the truth
            assert single.reduced_deviance_ > 1.3 and single.quality_factor_ < 0.95 * q
            assert check["reduced_deviance"] < 1.1
            assert check["main"]["quality_factor"] == pytest.approx(q, rel=0.05)
            assert check["second"]["frequency_hz"] == pytest.approx(178.9e3, abs=200)
            assert check["supported"] and check["deviance_drop"] > 10 * check["critical_drop"]
        else:
            assert single.reduced_deviance_ < 1.1
            assert check["reduced_deviance"] > single.reduced_deviance_ - 0.05
            assert not check["supported"]


@pytest.mark.slow
def test_interval_coverage_over_many_synthetic_spectra():
    """Calibration of the 95 % intervals with a resolved line (Hann, bins 244 Hz, line width
    667 Hz): over 25 independent spectra the truth must be inside in >= 80 % (nominal 95 %:
    fewer than 20 of 25 has probability ~0.007). Measured: f0 23/25, Q 25/25, k 25/25; with
    a line narrower than a bin (N = 1024) Q's spread is 1.4x the reported one (31/40)."""
    hits = {name: 0 for name in TRUTH}
    n = 25
    for seed in range(100, 100 + n):
        fit = _fit(_spectrum(seed, segment_length=4096, window=Hann(), n_segments=60),
                   WindowResponse(Hann(), 4096))
        for name, value in TRUTH.items():
            lo, hi = fit.intervals_[name]
            hits[name] += lo <= value <= hi
    for name, count in hits.items():
        assert count / n >= 0.8, (name, count, n)


def test_sandwich_covariance_matches_a_dense_reference():
    """The banded sandwich of `NoiseModel.covariance` against the dense ``I^-1 G^T R G I^-1``
    with the full Toeplitz correlation matrix R; independent bins give ``I^-1``."""
    from scipy.linalg import toeplitz

    rng = np.random.default_rng(0)
    jac = rng.normal(size=(300, 3))
    expected = rng.uniform(1.0, 2.0, 300)
    observed = expected * rng.gamma(50, 1 / 50, 300)
    noise = GammaLikelihood()
    rho = bin_correlation(Hann(), 1024)
    g = np.sqrt(50 / expected**2)[:, None] * jac
    info_inv = np.linalg.inv(g.T @ g)
    r = toeplitz(np.r_[rho, np.zeros(300 - len(rho))])
    dense = info_inv @ (g.T @ r @ g) @ info_inv
    np.testing.assert_allclose(noise.covariance(jac, observed, expected, 50, correlation=rho),
                               dense, rtol=1e-10)
    np.testing.assert_allclose(noise.covariance(jac, observed, expected, 50), info_inv,
                               rtol=1e-10)
