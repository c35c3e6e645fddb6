"""Known answers of the dissipative causes on set-point series: a loss out of contact is not
named a loss in contact, and vice versa (docs/diagnose.md, "The dissipative causes on
set-point series").

Constructed draws (every parameter chosen, not drawn; 4 set-points x 20 periods, 200
samples/period, 1 % noise, recorded drive phase): a long-range damping on a stiff sample
(5 GPa; 2e-7 N s/m decaying over 5 nm: it takes energy before the tip touches) and a
visco-elastic loss on a soft one (1 GPa; the generating law, DMT + ``eta sqrt(delta)
delta'``, is exactly the visco-elastic extension's family).
"""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.diagnose import Diagnoser
from afmlearn.diagnose.diagnoser import tie_margin
from afmlearn.diagnose.hypotheses import AdhesionHysteresis, LongRangeDamping, Viscoelastic
from afmlearn.diagnose.synthetic import SeriesCase, simulate_series
from afmlearn.io import read_trace

N_POINTS = 4
COMMON = {"quality_factor": 300.0, "free_amplitude_m": 25e-9,
          "setpoints": tuple(np.linspace(0.85, 0.35, N_POINTS).tolist()),
          "settle_offsets": tuple((0.37 * k) % 1 for k in range(N_POINTS)),
          "tip_radius_m": 10e-9, "hamaker_j": 1e-19, "a0_m": 0.3e-9, "seed": 3}
CASES = {
    "long_range_damping": SeriesCase(
        causes=("long_range_damping",), reduced_modulus_pa=5e9,
        effects={"long_range_damping": {"coefficient_ns_per_m": 2e-7,
                                        "decay_length_m": 5e-9}}, **COMMON),
    "viscoelastic": SeriesCase(
        causes=("viscoelastic",), reduced_modulus_pa=1e9,
        effects={"viscoelastic": {"viscosity_si": 0.03}}, **COMMON),
}


@pytest.fixture(scope="module")
def constructed(tmp_path_factory):
    folder = tmp_path_factory.mktemp("dissipative")
    cache = {}

    def make(cause: str):
        if cause not in cache:
            path = folder / f"series-{len(cache)}.h5"
            simulate_series(CASES[cause], path, n_periods=20.0)
            dg = Diagnoser(hypotheses=[Viscoelastic(), LongRangeDamping(),
                                       AdhesionHysteresis()],
                           max_causes=1, all_gains=True).fit(read_trace(path))
            cache[cause] = dg
        return cache[cause]

    return make


def _cands(dg: Diagnoser) -> dict:
    return {c.cause: c for c in dg.candidates_}


def test_damping_out_of_contact_is_not_named_viscoelastic(constructed):
    """The damping term explains the loss (measured: chi2 drop 4,722 against the visco-elastic
    term's 1,663, held-out gain 0.54 against 0.02): the in-contact term cannot take a loss that
    starts before contact, so the two are not even tied. The baseline (chi2 19,972) is
    re-based on the neck's point (5,487) and the damping fit (17,525 from the poor baseline)
    is refitted from there (765). Regression test of f9218b0: before it, the visco-elastic
    fit (3,824) kept its drop against the old baseline (16,148 instead of 1,663) and led the
    evidence; only its held-out gain (0.016, below 0.05) kept it from being named."""
    dg = constructed("long_range_damping")
    c = _cands(dg)
    assert dg.cause_ == "long_range_damping", dg.candidates_
    damping, visco = c["long_range_damping"], c["viscoelastic"]
    assert damping.score > visco.score + tie_margin(damping.delta_chi2), dg.candidates_


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "visco-elastic search failure not fixed on the committed tree: at 460296f the visco fit "
    "ends at chi2 332 (truth refit 162) and the damping term (186) is named; the energy start "
    "(d661e3e) is shot warm from the output error's previous orbits, and its acceptance run "
    "(168, named visco) was not reproduced on the committed code"))
def test_viscoelastic_loss_is_not_named_damping(constructed):
    """The generating law is in the visco-elastic family (its refit from the truth: chi2 162
    for 4 x 83 rows), so the visco-elastic extension should reach the noise and be named.
    Measured (session 6): the conservative baseline moves the contact onset out (7x the true
    one) to mimic the loss, and from there the equation error gives a coefficient far below
    the truth's: the fit from that start alone ended at chi2 11,938 and the damping term (223,
    held-out gain 0.96) was named (strict xfail until then). With the energy-balance start
    (``fit.energy_starts``: the coefficient from drive input minus lever loss per set-point)
    the visco-elastic fit reached 168 in one development run (held-out NRMSE 0.0036 against the
    damping term's 0.0044) and was named; on the committed tree it ends at 332 (xfail above)."""
    dg = constructed("viscoelastic")
    c = _cands(dg)
    assert dg.cause_ == "viscoelastic", dg.candidates_
    # the visco-elastic fit reaches the noise: as good as the damping term's, or better
    assert c["viscoelastic"].chi2 <= 1.1 * c["long_range_damping"].chi2, dg.candidates_
    assert c["viscoelastic"].gain > 0.5
