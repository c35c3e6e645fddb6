"""Forward selection with swaps: finds a pair that one greedy step would miss."""

from __future__ import annotations

import numpy as np

from afmlearn.identify.optimizers import BoxSR3
from afmlearn.identify.stepwise import ForwardSelection, cv_errors


def _problem(seed: int = 0):
    rng = np.random.default_rng(seed)
    n = 2000
    a, b = rng.normal(size=n), rng.normal(size=n)
    decoy = a + b + 0.05 * rng.normal(size=n)  # best single term, but not in the truth
    noise_cols = rng.normal(size=(n, 4))
    theta = np.column_stack([rng.normal(size=n), a, b, decoy, noise_cols])
    y = 0.5 * theta[:, 0] + 1.0 * a + 1.2 * b + 0.01 * rng.normal(size=n)
    return theta, y


def test_forward_selection_with_swaps_recovers_the_true_pair():
    theta, y = _problem()
    blocks = [(i * 200, (i + 1) * 200) for i in range(10)]
    opt = BoxSR3(threshold=1e-6, lower=[0.4] + [-np.inf] * 7, upper=[0.6] + [np.inf] * 7)
    fs = ForwardSelection(opt, always=[0], max_terms=3).fit(theta, y, blocks)
    two = [c for c in fs.candidates_ if c.n_terms == 3][0]
    assert set(np.flatnonzero(two.coef[0])) == {0, 1, 2}
    np.testing.assert_allclose(two.coef[0][[0, 1, 2]], [0.5, 1.0, 1.2], rtol=5e-3)
    # CV errors of the truth are at the noise level, the decoy's are not
    supp = np.zeros(8, bool)
    supp[[0, 1, 2]] = True
    e_true = cv_errors(opt, theta, y, blocks, supp)
    supp_d = np.zeros(8, bool)
    supp_d[[0, 3]] = True
    e_decoy = cv_errors(opt, theta, y, blocks, supp_d)
    assert np.all(e_true < e_decoy)
