"""The identifier's one-dimensional search: grid, then bounded refinement."""

import math

import numpy as np
import pytest

from afmlearn.identify.line_search import grid_then_bounded


def test_refines_between_neighbours_to_the_analytic_minimum() -> None:
    grid = np.geomspace(0.1, 10.0, 9)
    x, v, vals = grid_then_bounded(lambda a: (math.log(a) - 0.3) ** 2 + 1.0, grid, maxiter=40,
                                   xatol=1e-9)
    assert x == pytest.approx(math.exp(0.3), rel=1e-5)
    assert v == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(vals, (np.log(grid) - 0.3) ** 2 + 1.0)
    assert v <= vals.min()


def test_never_worse_than_the_grid_and_end_points_are_not_refined() -> None:
    grid = np.linspace(0.0, 1.0, 6)
    calls: list[float] = []

    def cost(a: float) -> float:
        calls.append(a)
        return a  # minimum at the lower end of the range

    x, v, _ = grid_then_bounded(cost, grid, maxiter=5)
    assert (x, v) == (0.0, 0.0)
    assert len(calls) == grid.size  # the end point is kept: no refinement ran


def test_failed_points_are_skipped_and_a_multimodal_cost_finds_the_grid_valley() -> None:
    grid = np.linspace(0.0, 4.0, 17)

    def cost(a: float) -> float:
        if 0.9 < a < 1.1:
            return math.nan  # a failed fit
        return min((a - 3.1) ** 2, (a - 0.6) ** 2 + 0.5)  # deeper valley at 3.1

    x, v, vals = grid_then_bounded(cost, grid, maxiter=30, xatol=1e-8)
    assert np.isnan(vals[4])
    assert x == pytest.approx(3.1, abs=1e-5) and v == pytest.approx(0.0, abs=1e-9)
    # a plain reference: dense brute force over the same range
    dense = np.linspace(0.0, 4.0, 40001)
    ref = dense[np.nanargmin([cost(float(a)) for a in dense])]
    assert x == pytest.approx(ref, abs=2e-4)


def test_all_points_failed_returns_the_first_without_refinement() -> None:
    x, v, vals = grid_then_bounded(lambda a: math.inf, np.array([1.0, 2.0, 3.0]), maxiter=3)
    assert x == 1.0 and math.isinf(v) and np.isinf(vals).all()
