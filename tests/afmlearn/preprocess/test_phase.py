"""The closed-form drive phase shared by the identifier's and the diagnosis' output-error fits."""

from __future__ import annotations

import math

import numpy as np

from afmlearn.preprocess.phase import align_phase, wrap_angle


def test_wrap_angle_range_and_types() -> None:
    assert wrap_angle(math.pi) == math.pi and wrap_angle(-math.pi) == math.pi
    assert abs(wrap_angle(3 * math.pi / 2) + math.pi / 2) < 1e-15
    a = wrap_angle(np.linspace(-20, 20, 101))
    assert isinstance(a, np.ndarray) and a.min() > -math.pi and a.max() <= math.pi


def test_align_phase_scalar_and_per_harmonic_sigma_agree_and_weights_matter() -> None:
    rng = np.random.default_rng(3)
    k = np.arange(10)
    X0 = (rng.normal(size=10) + 1j * rng.normal(size=10)) / (1 + k)
    phi = -2.3
    Y = X0 * np.exp(-1j * k * phi)
    assert abs(wrap_angle(align_phase(X0, Y, 0.1) - phi)) < 1e-10
    assert align_phase(X0, Y, 0.1) == align_phase(X0, Y, np.full(10, 0.1))
    # harmonic 1 says phi, harmonic 2 says phi + 0.4 / 2: the better-known one wins
    Y2 = Y.copy()
    Y2[2:] = 0
    Y2[2] = X0[2] * np.exp(-2j * (phi + 0.2))
    sig = np.ones(10)
    sig[2] = 1e-3
    assert abs(wrap_angle(align_phase(X0, Y2, sig) - (phi + 0.2))) < 1e-3
    sig[2], sig[1] = 1.0, 1e-3
    assert abs(wrap_angle(align_phase(X0, Y2, sig) - phi)) < 1e-3
