"""A law fitted on one curve predicts another curve of the same tip at another free
amplitude: the unit change keeps the SI force, and the true law predicts the other curve."""

from __future__ import annotations

import math

import numpy as np
import pytest

from afmlearn.curves import Curve, CurveLaw, SlowFlowModel
from afmlearn.curves.transfer import law_from_parameters, rescale_law, transfer_nrmse

K_N, Q = 2.7, 150.0
# one SI law (every term), written in units of L1 = 20 nm
L1, L2 = 20e-9, 45e-9
LAW1 = CurveLaw(a0=0.3e-9 / L1, vdw=2e-6, stiffness=40.0, exponent=1.5, damping=2e-3,
                decay_length=1.5, visco=0.05, electrostatic=1e-5, radius=10e-9 / L1,
                neck=0.02, far_damping=1e-4, far_decay_length=8.0)


def test_rescaled_law_is_the_same_si_force():
    law2 = rescale_law(LAW1, L1 / L2)
    z_si = np.array([0.1e-9, 0.2e-9, 1e-9, 5e-9, 30e-9])       # gaps [m], in and out of contact
    zd_si = 3e-9                                                # rate [m per unit omega0 t]
    for mode in (0, 1, 2):
        f1 = LAW1.force(z_si / L1, zd_si / L1, mode) * K_N * L1
        f2 = law2.force(z_si / L2, zd_si / L2, mode) * K_N * L2
        np.testing.assert_allclose(f2, f1, rtol=1e-12)
    assert law2.neck * L2 == pytest.approx(LAW1.neck * L1)
    with pytest.raises(ValueError, match="ratio"):
        rescale_law(LAW1, 0.0)


def synthetic(law_si_unit: CurveLaw, length_m: float, offset: float) -> Curve:
    """A noise-free approach--retract curve of free amplitude ``length_m`` (model data)."""
    law = rescale_law(law_si_unit, L1 / length_m)
    n = 500
    tau = 2 * math.pi * 6 * np.arange(2 * n)
    gap = np.concatenate([np.linspace(2.5, 0.5, n), np.linspace(0.5, 2.5, n)])
    model = SlowFlowModel(quality_factor=Q, omega=1.0, drive=1.0 / Q, step=4 * math.pi)
    amp, phi = model.predict(law, tau, gap)
    return Curve(tau=tau, amplitude=amp, phase=phi, z_piezo=gap + offset,
                 segment=np.repeat(np.array([0, 1], dtype=np.int8), n), quality_factor=Q,
                 spring_constant_n_per_m=K_N, resonance_frequency_hz=70e3, length_m=length_m,
                 drive_frequency_hz=70e3)


def test_the_true_law_predicts_another_free_amplitude():
    other = synthetic(LAW1, L2, offset=3.0)
    assert np.min(other.amplitude) < 0.8  # the tip meets the surface
    true = transfer_nrmse(LAW1, L1, other)
    wrong = transfer_nrmse(LAW1.replace(vdw=LAW1.vdw * 30, damping=0.0), L1, other)
    assert true["nrmse"] < 2e-3 and true["offset"] == pytest.approx(3.0, abs=0.02)
    assert wrong["nrmse"] > 5 * true["nrmse"]


def test_law_from_report_parameters():
    law = law_from_parameters({"offset": 1.0, "omega": 1.0, "vdw": 3e-6, "damping": 1e-3}, L1)
    assert law.vdw == 3e-6 and law.damping == 1e-3 and law.a0 == pytest.approx(0.3e-9 / L1)


def test_transfer_gains_of_the_true_extension_are_positive():
    """Curves of one tip at 20, 30 and 45 nm made with long-range damping: the law with the
    damping predicts the other curves better than the same law without it."""
    from afmlearn.curves.transfer import transfer_gains

    lengths = {"g/a": 20e-9, "g/b": 30e-9, "g/c": 45e-9}
    curves = {k: synthetic(LAW1, v, offset=1.0) for k, v in lengths.items()}
    rows = []
    for k, v in lengths.items():
        ext = rescale_law(LAW1, L1 / v).parameters()
        rows.append({"file": k, "group": "g", "cause": "long_range_damping",
                     "free_amplitude_m": v, "parameters": ext,
                     "baseline_parameters": {**ext, "damping": 0.0}})
    out = transfer_gains({"curves": rows}, "/nowhere", n_sources=2, n_targets=2,
                         load=lambda p: (curves[f"{p.parent.name}/{p.name}"], None))
    assert len(out["pairs"]) == 4
    assert all(p["source"] != p["target"] for p in out["pairs"])
    assert out["gain_positive"] == 1.0 and out["median_gain"] > 0.5
