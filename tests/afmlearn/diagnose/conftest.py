"""Fixtures of the diagnosis tests: hidden-effect traces made once per session."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from afmlearn.diagnose.synthetic import Case, SeriesCase, hidden_series, hidden_trace


@pytest.fixture(scope="session")
def make_trace(tmp_path_factory):
    """``make_trace(cause, seed, spp=200, periods=300, noise=0.01) -> (path, case)``.

    The cause is forced (the parameters are drawn); the file name says nothing about it.
    """
    cache: dict[tuple, tuple[Path, Case]] = {}
    folder = tmp_path_factory.mktemp("diagnose")

    def make(cause: str | None, seed: int, *, spp: int = 200, periods: float = 300.0,
             noise: float = 0.01) -> tuple[Path, Case]:
        key = (cause, seed, spp, periods, noise)
        if key not in cache:
            path = folder / f"trace-{len(cache):03d}.h5"
            case = hidden_trace(np.random.default_rng([seed, 77]), path, cause=cause,
                                samples_per_period=spp, n_periods=periods, noise_level=noise)
            cache[key] = (path, case)
        return cache[key]

    return make


@pytest.fixture(scope="session")
def make_series(tmp_path_factory):
    """``make_series(causes, seed, n_points=4, spp=200, periods=20, noise=0.01,
    drive_phase=True) -> (path, case)``: a small hidden-effect set-point series (the causes
    forced, every parameter drawn; neutral file name)."""
    cache: dict[tuple, tuple[Path, SeriesCase]] = {}
    folder = tmp_path_factory.mktemp("diagnose-series")

    def make(causes: str, seed: int, *, n_points: int = 4, spp: int = 200,
             periods: float = 20.0, noise: float = 0.01, drive_phase: bool = True
             ) -> tuple[Path, SeriesCase]:
        key = (causes, seed, n_points, spp, periods, noise, drive_phase)
        if key not in cache:
            path = folder / f"series-{len(cache):03d}.h5"
            case = hidden_series(np.random.default_rng([seed, 78]), path, causes=causes,
                                 n_points=n_points, samples_per_period=spp,
                                 n_periods=periods, noise_level=noise,
                                 drive_phase=drive_phase)
            cache[key] = (path, case)
        return cache[key]

    return make


@pytest.fixture
def labels_guarded(monkeypatch) -> list[str]:
    """Make the diagnosis' trace reader fail loudly if asked for the labels; returns the
    paths it read (a test checks the guard was on the path actually taken)."""
    import afmlearn.io.reader as reader

    real = reader.read_trace
    reads: list[str] = []

    def guarded(p, *a, labels=False, **kw):
        assert not labels, "diagnosis asked for the labels"
        reads.append(str(p))
        return real(p, *a, labels=labels, **kw)

    monkeypatch.setattr("afmlearn.diagnose.report.read_trace", guarded)
    return reads
