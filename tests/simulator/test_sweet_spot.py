"""Sweet-spot acceptance: the 2-mode Table 3.B.1 model shows the 6:1 internal-resonance physics.

The fast test sweeps the start of the thesis sweep (the first 106 of its 501 points,
``Omega = 0.990149 ... 1.0201``, 50,000 samples per point at 1,500 per period, so the forward
dynamics is the thesis sweep's) for the 2-mode model and for the 1-mode model with the same
mode-1 numbers, and checks the qualitative physics reported in ``docs/sweet_spot.md``:

* the 2-mode tip taps near ``Omega = 1``; above it, in a window of the tapping branch, the 6th
  harmonic of the tip deflection rises several-fold relative to its value at ``Omega ~ 1``
  and the coupling strength (share of mode 2) rises with it;
* the 1-mode model, same parameters, taps too but has no 6th-harmonic resonance: its 6th
  harmonic (the impact harmonic filtered by mode 1) stays two orders of magnitude smaller.

The slow test runs the whole thesis sweep (501 points, forward and reverse) and checks the
jumps: softening and hysteresis at the onset of tapping, the reverse sweep passing the sweet
spot on the low branch, and the 1-mode tapping branch hardening to the end of the range.
"""

from __future__ import annotations

import numpy as np
import pytest

from simulator import BaseExcitation, Cantilever, Sweep, System
from simulator.forces import DMT
from simulator.labels import lock_in

# Table 3.B.1 (physics.md section 2); C1 chosen in docs/sweet_spot.md
OMEGA_START, OMEGA_STOP, N_THESIS = 0.990149, 1.1327, 501
STEP = (OMEGA_STOP - OMEGA_START) / (N_THESIS - 1)
C1 = 6e-4
A0 = 0.2


def _system(n_modes: int) -> System:
    if n_modes == 2:
        cl = Cantilever(stiffness=[1.0, 36.0], damping=[2.9e-3, 5e-4],
                        contact_damping=[5.7e-3, 8e-3],
                        base_participation=[1.565980, -0.867872], force_gain=[1.0, 13.5 / 10.5])
    else:
        cl = Cantilever(stiffness=[1.0], damping=[2.9e-3], contact_damping=[5.7e-3],
                        base_participation=[1.565980])
    return System(cl, DMT(a0=A0, vdw=C1, stiffness=10.5), BaseExcitation(amplitude=2.649109e-3))


def _sweep(n_modes: int, n_points: int, direction: str) -> dict[str, dict[str, np.ndarray]]:
    """Per-point features (forward-frequency order) of each direction of the sweep."""
    sw = Sweep(omega_start=OMEGA_START, omega_stop=OMEGA_START + (n_points - 1) * STEP,
               n_points=n_points, samples_per_point=50_000, samples_per_period=1500,
               direction=direction)
    out = {d: {k: np.empty(n_points) for k in ("omega", "a1", "a6", "coupling", "contact",
                                                "amp")} for d in sw.directions}
    for p in sw.iter_points(_system(n_modes)):
        k = p.row % n_points
        i = k if p.direction == "forward" else n_points - 1 - k
        x = p.q.sum(axis=0)
        # lock-in over whole drive periods: otherwise the leakage of the fundamental (~1e-3)
        # would swamp the 1-mode model's small 6th harmonic
        n = int(np.floor(x.size * p.omega / 1500) * 1500 / p.omega)
        d = out[p.direction]
        d["omega"][i] = p.omega
        d["a1"][i] = abs(lock_in(x[:n], p.phase[:n], 1))
        d["a6"][i] = abs(lock_in(x[:n], p.phase[:n], 6))
        d["coupling"][i] = p.labels["coupling_strength"]
        d["contact"][i] = p.labels["contact_fraction"]
        d["amp"][i] = 0.5 * (x.max() - x.min())
    return out


def _window(d: dict[str, np.ndarray]) -> tuple[int, np.ndarray]:
    """Index of the point nearest Omega = 1 and the mask of the window (Omega(ref), 1.02]."""
    i1 = int(np.argmin(np.abs(d["omega"] - 1.0)))
    return i1, (d["omega"] > d["omega"][i1]) & (d["omega"] <= 1.02)


@pytest.fixture(scope="module")
def start_of_thesis_sweep() -> tuple[dict, dict]:
    return _sweep(2, 106, "forward")["forward"], _sweep(1, 106, "forward")["forward"]


def test_two_mode_sixth_harmonic_and_coupling_rise_above_resonance(start_of_thesis_sweep):
    two, _ = start_of_thesis_sweep
    i1, win = _window(two)
    assert two["contact"][i1] > 0.0, "the 2-mode tip must tap at Omega ~ 1"
    a6 = np.where(win, two["a6"], 0.0)
    k = int(np.argmax(a6))
    # several-fold rise of the 6th harmonic on the tapping branch above Omega = 1 (x3 measured)
    assert a6[k] >= 2.5 * two["a6"][i1]
    assert two["contact"][k] > 0.0
    # harmonic content relative to the fundamental rises too (x3.5 measured)
    assert two["a6"][k] / two["a1"][k] >= 2.5 * two["a6"][i1] / two["a1"][i1]
    # mode 2 takes a growing share of the motion there (x13 measured)
    assert two["coupling"][k] >= 5.0 * two["coupling"][i1]


def test_one_mode_model_shows_no_sixth_harmonic_resonance(start_of_thesis_sweep):
    two, one = start_of_thesis_sweep
    i1, win = _window(one)
    assert one["contact"][i1] > 0.0, "the 1-mode tip taps at Omega ~ 1 as well"
    assert np.all(one["coupling"] == 0.0)
    # Without mode 2 the 6th harmonic is only the impact harmonic filtered by mode 1
    # (~F6 / 35): it grows slowly with the indentation along the tapping branch (x3.8 over
    # the window, measured) but stays two orders of magnitude below the 2-mode sweet spot
    # (0.5 % measured) and never becomes a noticeable part of the motion (X6/X1 < 0.1 %).
    _, win2 = _window(two)
    assert one["a6"][win].max() <= 0.02 * two["a6"][win2].max()
    assert np.max(one["a6"][win] / one["a1"][win]) < 0.002
    assert np.max(two["a6"][win2] / two["a1"][win2]) > 0.1


@pytest.mark.slow
def test_thesis_sweep_softening_hysteresis_and_hardening():
    two = _sweep(2, N_THESIS, "both")
    one = _sweep(1, N_THESIS, "both")
    fw, rv = two["forward"], two["reverse"]
    # 6th-harmonic rise in the forward sweep, as in the fast test
    i1, win = _window(fw)
    assert fw["a6"][win].max() >= 2.5 * fw["a6"][i1]
    # upper (tapping) branch: amplitude ~0.85 L_ref, low branch < 0.5 L_ref
    high, rhigh = fw["amp"] > 0.5, rv["amp"] > 0.5
    # reverse: the low branch is followed through the sweet spot ...
    assert not rhigh[rv["omega"] > 1.005].any()
    # ... and the upper branch reached near Omega = 1 extends below the forward onset
    # (attractive softening, hysteresis of the jumps)
    assert rv["omega"][rhigh].min() < fw["omega"][high].min() - 0.001
    # forward: tapping from below Omega = 1 on
    assert fw["omega"][high].min() < 1.0
    # 1 mode, same parameters: no internal resonance; the tapping branch hardens through the
    # whole range without a jump. (Whether the 2-mode forward sweep leaves the tapping branch
    # after the sweet spot depends sensitively on C1 and on the numerics: not asserted.)
    o_high = one["forward"]["amp"] > 0.5
    assert o_high[one["forward"]["omega"] > 1.0].all()
