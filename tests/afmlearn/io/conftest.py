"""Small traces shared by the io tests."""

from __future__ import annotations

from typing import Any

import h5py
import numpy as np
import pytest

from afmlearn.io import Labels, Trace

N = 256
N_POINTS = 5
N_MODES = 2


@pytest.fixture
def calibration() -> dict[str, Any]:
    return {
        "sample_rate_hz": 5.0e6,
        "spring_constant_n_per_m": 40.0,
        "quality_factor": 400.0,
        "resonance_frequency_hz": 3.0e5,
    }


@pytest.fixture
def single(calibration: dict[str, Any]) -> Trace:
    """A single trace with every optional field and labels."""
    rng = np.random.default_rng(0)
    deflection = 1e-8 * rng.standard_normal(N)
    modal = 1e-8 * rng.standard_normal((N_MODES, N))
    return Trace(
        deflection,
        **calibration,
        drive_frequency_hz=2.99e5,
        gap_m=np.linspace(20e-9, 5e-9, N),
        free_amplitude_m=10e-9,
        excitation="base",
        dither_amplitude_m=0.1e-9,
        higher_mode_frequencies_hz=np.array([1.9e6, 5.2e6]),
        tip_radius_m=8e-9,
        description="approach ramp",
        free_deflection_m=1e-8 * rng.standard_normal(64),
        labels=Labels(
            1e-9 * rng.standard_normal(N),
            modal_m=modal,
            model={"name": "vdw_dmt", "hamaker_j": 1e-19, "modes": [1, 2]},
            effect="higher_mode",
            scalars={"dissipated_energy_j": 1.5e-19, "regime": "attractive"},
            extra={"gap_true_m": np.linspace(20e-9, 5e-9, N)},
        ),
    )


@pytest.fixture
def sweep(calibration: dict[str, Any]) -> Trace:
    """A sweep of N_POINTS rows, minimal metadata, labels with per-row scalars."""
    rng = np.random.default_rng(1)
    shape = (N_POINTS, N)
    return Trace(
        1e-8 * rng.standard_normal(shape),
        **calibration,
        drive_frequency_hz=np.linspace(2.9e5, 3.1e5, N_POINTS),
        gap_m=15e-9,
        labels=Labels(
            1e-9 * rng.standard_normal(shape),
            modal_m=1e-8 * rng.standard_normal((N_MODES, *shape)),
            model={"name": "vdw_dmt"},
            scalars={
                "contact_fraction": np.linspace(0.0, 0.4, N_POINTS),
                "coupling_strength": 0.3,
            },
        ),
    )


def assert_same_trace(a: Trace, b: Trace, *, labels: bool) -> None:
    """Equal arrays and metadata; labels compared when ``labels``."""
    np.testing.assert_array_equal(a.deflection_m, b.deflection_m)
    for name, value in a.metadata().items():
        other = b.metadata()[name]
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(value, other, err_msg=name)
        else:
            assert value == other, name
    if not labels:
        return
    assert a.labels is not None and b.labels is not None
    np.testing.assert_array_equal(a.labels.force_n, b.labels.force_n)
    np.testing.assert_array_equal(a.labels.modal_m, b.labels.modal_m)
    assert a.labels.model == b.labels.model
    assert a.labels.effect == b.labels.effect
    assert a.labels.scalars.keys() == b.labels.scalars.keys()
    for name, value in a.labels.scalars.items():
        np.testing.assert_array_equal(value, b.labels.scalars[name], err_msg=name)
    assert a.labels.extra.keys() == b.labels.extra.keys()
    for name, value in a.labels.extra.items():
        np.testing.assert_array_equal(value, b.labels.extra[name], err_msg=name)


@pytest.fixture
def assert_same() -> Any:
    """`assert_same_trace`, as a fixture (test modules here are not importable)."""
    return assert_same_trace


@pytest.fixture
def h5_names_seen(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Every name looked up in an HDF5 group (``[]``, ``get``, ``in``) from now on: a spy that
    proves which groups a reader touches (e.g. never ``/labels``)."""
    seen: list[str] = []
    for method in ("__getitem__", "get", "__contains__"):
        original = getattr(h5py.Group, method)

        def spy(self: h5py.Group, name: Any, *args: Any, _original: Any = original) -> Any:
            seen.append(str(name))
            return _original(self, name, *args)

        monkeypatch.setattr(h5py.Group, method, spy)
    return seen
