"""The Sader--Jarvis peer (benchmarks/bench_fm_inversion.py) on forces with a known answer:
Giessibl's Δf of an analytic force, inverted back."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from bench_fm_inversion import sader_jarvis  # noqa: E402

from afmlearn.fm import frequency_shift  # noqa: E402


def morse(d):
    """Attractive--repulsive force [k L] (> 0 repulsive), range ~1 L."""
    return 2e-3 * np.exp(-(d - 1.0) / 0.3) - 1e-3 * np.exp(-(d - 1.0) / 1.0)


@pytest.mark.parametrize("amplitude", [0.05, 1.0, 10.0])
def test_sader_jarvis_recovers_a_known_force_at_small_and_large_amplitude(amplitude):
    z = np.linspace(0.8, 12.0, 561)
    omega = frequency_shift(morse, z, amplitude=amplitude, n_nodes=512)
    f = sader_jarvis(z, omega, amplitude=amplitude)
    true = morse(z) - morse(z[-1])
    keep = z < 6.0
    err = np.max(np.abs(f[keep] - true[keep])) / np.ptp(true[keep])
    assert err < 0.05  # the formula's own accuracy (Sader & Jarvis 2004: within ~5 %)


def test_sader_jarvis_small_amplitude_limit_is_the_integral_of_the_shift():
    # A -> 0: F(z) = 2 k int_z^inf Omega dt, Omega = -F'/(2k): F of a linear gradient
    z = np.linspace(0.0, 5.0, 201)
    omega = np.full_like(z, -0.01)  # constant attractive gradient F' = 0.02 k
    f = sader_jarvis(z, omega, amplitude=1e-8, stiffness=3.0)
    np.testing.assert_allclose(f[:-2], 2 * 3.0 * -0.01 * (z[-1] - z[:-2]), rtol=1e-3)


def test_sader_jarvis_rejects_unsorted_positions():
    with pytest.raises(ValueError, match="increasing"):
        sader_jarvis([3.0, 2.0, 1.0, 0.0], [0.0] * 4, amplitude=1.0)
