"""Hidden-unit interpretation: correlations, per-point averaging, rankings and the figure."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from afmlearn.plots.qrnn import plot_unit_activation
from afmlearn.qrnn.interpret import interpret_sweep, pearson, point_activations, rank_units


def test_pearson_matches_numpy_and_is_zero_for_constants():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(30, 4))
    a[:, 2] = 5.0
    b = rng.normal(size=30) + a[:, 0]
    r = pearson(a, b)
    for j in (0, 1, 3):
        assert r[j] == pytest.approx(np.corrcoef(a[:, j], b)[0, 1], abs=1e-12)
    assert r[2] == 0.0
    np.testing.assert_array_equal(pearson(a, np.ones(30)), np.zeros(4))


class _FakeModule:
    """predict_windows returns, per window, the mean over time of a known map of the input."""

    def predict_windows(self, x):
        xm = x.mean(dim=1)                               # (N, F)
        return {"activation": torch.stack([xm[:, 0], -xm[:, 1], xm[:, 0] * 0 + 1.0,
                                           xm[:, 2] ** 2], dim=1)}


def test_interpret_sweep_finds_the_planted_units(tmp_path):
    rng = np.random.default_rng(0)
    n_points, per = 25, 3
    omega = np.linspace(0.98, 1.03, n_points)
    share2 = np.exp(-((omega - 1.01) / 0.008) ** 2) * 0.2          # peaks in the "sweet spot"
    shares = np.stack([1 - share2, share2, np.zeros(n_points)], axis=1)
    point = np.repeat(np.arange(n_points), per)
    x = np.zeros((n_points * per, 8, 3), dtype=np.float32)
    x[:, :, 0] = (shares[point, 1] + 0.001 * rng.normal(size=point.size))[:, None]
    x[:, :, 1] = omega[point][:, None]                             # unit 1 = -omega
    x[:, :, 2] = rng.normal(size=(point.size, 8))                  # unit 3 = noise
    ids, act = point_activations(_FakeModule(), x, point)
    np.testing.assert_array_equal(ids, np.arange(n_points))
    np.testing.assert_allclose(act[:, 1], -omega, rtol=1e-6)      # averaged per point
    sweet = (np.abs(omega - 1.01) < 0.006).astype(float)
    order = np.random.default_rng(2).permutation(point.size)       # window order is irrelevant
    res = interpret_sweep(_FakeModule(), x[order], point=point[order], omega=omega[point][order],
                          shares=shares[point][order], sweet=sweet[point][order], top=2)
    np.testing.assert_allclose(res.omega, omega)
    targets = {r.target: r for r in res.rankings}
    assert list(targets) == ["mode 1 share", "mode 2 share", "drive frequency", "sweet spot"]
    assert targets["mode 2 share"].units[0] == 0 and targets["mode 2 share"].r[0] > 0.99
    assert targets["mode 1 share"].units[0] == 0 and targets["mode 1 share"].r[0] < -0.99
    assert targets["drive frequency"].units[0] == 1
    assert targets["drive frequency"].r[0] == pytest.approx(-1.0)
    path = plot_unit_activation(res, tmp_path / "units.png")
    assert path.is_file() and path.stat().st_size > 5000


def test_rank_units_rejects_bad_arguments():
    with pytest.raises(ValueError, match="top"):
        rank_units(np.zeros((5, 3)), {"a": np.arange(5)}, top=4)
    with pytest.raises(ValueError, match="activation"):
        rank_units(np.zeros((2, 3)), {"a": np.arange(2)})


def test_interpretation_of_a_trained_module(tiny_run, tmp_path):
    """On real windows: one ranking per target, |r| sorted, units valid."""
    dm = tiny_run["objects"]["datamodule"]
    module = tiny_run["objects"]["model"]
    data = dm.dataset("test")[list(range(len(dm.dataset("test"))))]
    shares = np.stack([1 - data["coupling"].numpy(), data["coupling"].numpy()], axis=1)
    key = data["sweep_id"].numpy() * 1000 + data["point"].numpy()
    res = interpret_sweep(module, data["x"], point=key, omega=data["omega"].numpy(),
                          shares=shares, top=3)
    assert res.activation.shape == (np.unique(key).size, module.net.hidden_size)
    for r in res.rankings:
        assert np.all(np.diff(np.abs(r.r)) <= 1e-12)
        assert np.all((r.units >= 0) & (r.units < module.net.hidden_size))
