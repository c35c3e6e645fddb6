"""Weak form: integration by parts is exact on smooth signals; projection == direct sums."""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.identify.weak import WeakForm


def test_integration_by_parts_identities():
    spp = 400
    tau = np.arange(20 * spp) * 2 * np.pi / spp
    x = np.sin(tau) + 0.3 * np.cos(3 * tau + 0.2)
    xd = np.cos(tau) - 0.9 * np.sin(3 * tau + 0.2)
    xdd = -np.sin(tau) - 2.7 * np.cos(3 * tau + 0.2)
    wf = WeakForm(half_width=0.3, stride=0.1)
    phi, dphi, ddphi = wf.kernels(spp, tau[1] - tau[0])
    c = wf.centres(tau.size, spp)
    np.testing.assert_allclose(wf.project(x, ddphi, c), wf.project(xdd, phi, c),
                               atol=1e-6 * np.abs(wf.project(xdd, phi, c)).max())
    np.testing.assert_allclose(-wf.project(x, dphi, c), wf.project(xd, phi, c),
                               atol=1e-6 * np.abs(wf.project(xd, phi, c)).max())


def test_projection_equals_direct_sum():
    rng = np.random.default_rng(0)
    f = rng.normal(size=(3000, 2))
    wf = WeakForm(half_width=0.1, stride=0.05)
    phi, _, _ = wf.kernels(200, 0.01)
    c = wf.centres(3000, 200)
    k = (phi.size - 1) // 2
    direct = np.array([[phi @ f[i - k:i + k + 1, j] for j in range(2)] for i in c])
    np.testing.assert_allclose(wf.project(f, phi, c), direct, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("kw", [dict(half_width=0), dict(stride=-1), dict(order=2)])
def test_bad_settings(kw):
    with pytest.raises(ValueError):
        WeakForm(**kw)


def test_too_short_trace():
    with pytest.raises(ValueError, match="too short"):
        WeakForm(half_width=1.0).centres(100, 200)
