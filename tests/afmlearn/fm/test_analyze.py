"""Pieces of the map analysis (afmlearn/fm/analyze.py): the held-out column split and the
residual split into parts even and odd in the bias about V_cpd."""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.fm import FMLaw, FMSpectroscopy, model_hz
from afmlearn.fm.analyze import _residual_structure, heldout_split

CAL = {"spring_constant_n_per_m": 1800.0, "amplitude_m": 0.5e-9,
       "resonance_frequency_hz": 19796.5}
LAW = FMLaw(hamaker_j=0.0, modulus_pa=0.0, tip_radius_m=5e-9, vcpd_v=1.0, es_radius_m=50e-9,
            es_setback_m=2e-9, z_contact_m=-31e-9)


def test_heldout_split_partitions_the_columns():
    fit, test = heldout_split(10, 4)
    assert sorted(np.concatenate([fit, test]).tolist()) == list(range(10))
    assert test.tolist() == [0, 4, 8]
    with pytest.raises(ValueError, match="heldout_every"):
        heldout_split(10, 1)


@pytest.mark.parametrize("kind", ["odd", "even"])
def test_a_perturbation_odd_or_even_in_the_bias_lands_in_its_part(kind):
    z = -30e-9 + 1e-9 * np.arange(6)
    bias = np.linspace(-3.0, 5.0, 33)  # symmetric about V_cpd = 1 V, 0.25 V steps
    spec0 = FMSpectroscopy(np.zeros((z.size, bias.size)), z, bias, **CAL)
    extra = 0.3 * (bias - 1.0) if kind == "odd" else 0.3 * np.cos(bias - 1.0)
    spec = FMSpectroscopy(model_hz(spec0, LAW) + extra[None, :], z, bias, **CAL)
    out = _residual_structure(spec, LAW)
    big, small = ((out["odd_in_bias_rms_hz"], out["even_in_bias_rms_hz"]) if kind == "odd"
                  else (out["even_in_bias_rms_hz"], out["odd_in_bias_rms_hz"]))
    assert small < 1e-9 < big
    assert out["rms_hz"] == pytest.approx(np.sqrt(np.mean(extra**2)), rel=1e-9)
