"""Ramps too fast for quasi-steady windows: the lag (gap change per settling time Q/pi periods)
against its analytic value, the warning naming the rate and the limit, no cause named above it,
and a null ramp at a realistic rate naming nothing with the default config."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from afmlearn.diagnose import Diagnoser
from afmlearn.diagnose.hypotheses import HigherMode
from afmlearn.diagnose.observation import MAX_RAMP_LAG, build_observations
from afmlearn.io import Trace, read_trace

CONF = Path(__file__).resolve().parents[3] / "conf"


def _linear_ramp(path, lag: float) -> Trace:
    """The rows of a steady series joined into one record with a linear gap ramp whose gap
    change per settling time is ``lag`` (in the mean gap, the diagnosis' L_ref)."""
    tr = read_trace(path)
    rows = [tr.row(i) for i in range(tr.n_points)]
    y = np.concatenate([r.deflection_m for r in rows])
    meta = rows[0].metadata()
    spp = meta["sample_rate_hz"] / meta["drive_frequency_hz"]
    g_mean = float(np.mean([r.gap_m for r in rows]))
    per_sample = lag * g_mean / (meta["quality_factor"] / math.pi) / spp
    gap = g_mean + per_sample * (np.arange(y.size) - (y.size - 1) / 2)
    return Trace(y, **{**meta, "gap_m": gap, "drive_phase_rad": None})


@pytest.mark.parametrize("lag", [0.1, 2.0])
def test_ramp_lag_is_the_gap_change_per_settling_time(make_series, lag):
    ramp = _linear_ramp(make_series("none", 3)[0], lag)
    warnings: list[str] = []
    obs = build_observations([ramp], phase_sd=0.02, window_periods=20.0, max_windows=3,
                             warnings=warnings)
    assert {o.kind for o in obs} == {"ramp_window"} and len(obs) == 3
    assert all(o.ramp_lag == pytest.approx(lag, rel=1e-6) for o in obs)
    (w,) = warnings
    c = obs[0].cal
    settle = c.quality_factor / math.pi
    si = c.scales.length * c.omega * c.scales.resonance_frequency      # L_ref/period -> m/s
    assert f"{100 * lag:.1f} % of L_ref" in w and f"{lag / settle * si * 1e9:.3g} nm/s" in w
    assert ("no cause is named" in w) == (lag > MAX_RAMP_LAG)
    if lag > MAX_RAMP_LAG:
        assert f"slower than {MAX_RAMP_LAG / settle * si * 1e9:.3g} nm/s" in w


def test_ramp_lag_is_not_inflated_by_a_noisy_gap_record(make_series):
    """A measured (Z-sensor) gap carries noise; the lag is a difference over one settling time
    (here half the 80-period record, scaled), so 0.01 nm rms noise moves it by at most
    ~2 x 4.5 sigma times that scale, where a sample-to-sample slope would multiply the noise
    by the samples per settling time (measured before: lag 346 for a true 0.01)."""
    ramp = _linear_ramp(make_series("none", 3)[0], 0.01)
    sigma = 1e-11
    noisy = Trace(ramp.deflection_m, **{**ramp.metadata(), "gap_m": ramp.gap_m
                  + np.random.default_rng(0).normal(0.0, sigma, ramp.gap_m.size)})
    obs = build_observations([noisy], phase_sd=0.02, window_periods=20.0, max_windows=3,
                             warnings=[])
    c = obs[0].cal
    span = min(c.quality_factor / math.pi, c.n_samples / c.samples_per_period / 2)   # periods
    bound = 2 * 4.5 * sigma / c.scales.length * (c.quality_factor / math.pi) / span
    assert 0.01 - bound <= obs[0].ramp_lag <= 0.01 + bound < MAX_RAMP_LAG


@pytest.mark.slow
def test_too_fast_ramp_names_no_cause(make_series):
    ramp = _linear_ramp(make_series("none", 3)[0], 2.0)
    dg = Diagnoser(hypotheses=[HigherMode()], max_ramp_windows=3).fit(ramp)
    assert dg.cause_ == "none" and dg.causes_ == [] and dg.candidates_ == []
    assert any("no cause is named" in w for w in dg.warnings_)
    # "none" because nothing was tested is no evidence for the baseline
    assert dg.confidence_ == 0.0 and "no cause was tested" in dg.untested_reason_


@pytest.mark.slow
def test_null_ramp_at_a_realistic_rate_names_nothing(tmp_path):
    """Plain DMT, the tapping lever, 2,000 periods per ramp (1.5 L_ref: 1.95 um/s, the Asylum
    curves' ~2 um/s; lag 8.5 % of L_ref per settling time), the DEFAULT diagnoser config:
    nothing named (above MAX_RAMP_LAG no cause is tested; measured without that limit: none
    too, and the exponent 1.50 [1.47, 3.50], while a visco-elastic ramp at this rate was
    named contact_geometry)."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from hydra.utils import instantiate
    from omegaconf import OmegaConf

    from afmlearn.simulate import simulate

    GlobalHydra.instance().clear()
    with initialize_config_dir(str(CONF), version_base="1.3"):
        cfg = compose("simulate", overrides=["scenario=approach", "scenario.n_periods=2000",
                                             "seed=1", "progress=false",
                                             f"output={tmp_path / 'a.h5'}"])
    simulate(cfg)
    dg = instantiate(OmegaConf.load(CONF / "diagnoser" / "default.yaml"))
    dg.fit(read_trace(tmp_path / "a.h5"))
    assert dg.cause_ == "none" and dg.causes_ == []
    (w,) = [w for w in dg.warnings_ if "no cause is named" in w]
    assert "8.5 % of L_ref" in w and "1.95e+03 nm/s" in w
    # the contact exponent is profiled with the contact_geometry cause: not reported either
    # (fast ramps gave 2.96 [2.93, 3.02] and 1.00 for a truth of 1.5)
    assert dg.exponent_interval_ is None
