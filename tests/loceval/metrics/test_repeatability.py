"""Repeatability of a path in space (loceval.metrics.repeatability): re-driven paths against a
baseline."""

from __future__ import annotations

import numpy as np
import pytest

from loceval.errors import InputError
from loceval.metrics.repeatability import PathDeviation, finite_positions, path_deviations


def test_known_distances_give_median_and_max() -> None:
    """Points 0, 0.1, 0.2 and 0.3 m above a straight baseline: median 0.15, max 0.3 (by hand)."""
    baseline = np.stack([np.linspace(0.0, 10.0, 11), np.zeros(11), np.zeros(11)], axis=1)
    heights = np.array([0.0, 0.1, 0.2, 0.3])
    path = np.stack([np.array([1.0, 3.5, 6.25, 9.0]), np.zeros(4), heights], axis=1)
    (deviation,) = path_deviations(baseline, [path])
    assert deviation.points == 4
    assert deviation.median_m == pytest.approx(0.15, abs=5e-4)  # within the index's 0.5 mm
    assert deviation.max_m == pytest.approx(0.3, abs=5e-4)
    assert deviation.median_m >= 0.15 - 1e-12  # never below the exact distance


def test_each_path_against_the_one_baseline(rng: np.random.Generator) -> None:
    """Circles of radius 2 m shifted 2 and 5 cm outwards are 0.02 and 0.05 m off everywhere."""
    s = np.linspace(0.0, 2 * np.pi, 3000)  # a closed loop: first vertex = last vertex
    circle = np.stack([np.cos(s), np.sin(s), np.full_like(s, 1.2)], axis=1)
    baseline = circle * np.array([2.0, 2.0, 1.0])
    t = rng.uniform(0.0, 2 * np.pi, 500)
    ring = np.stack([np.cos(t), np.sin(t), np.full_like(t, 1.2)], axis=1)
    near, far = ring * np.array([2.02, 2.02, 1.0]), ring * np.array([2.05, 2.05, 1.0])
    deviations = path_deviations(baseline, [near, far])
    assert [d.points for d in deviations] == [500, 500]
    # chords sit inside the circle by at most 2 * (1 - cos(pi / 2999)) ~ 1.1e-6 m; index 0.5 mm
    assert deviations[0].median_m == pytest.approx(0.02, abs=6e-4)
    assert deviations[1].max_m == pytest.approx(0.05, abs=6e-4)
    assert path_deviations(baseline, []) == ()


def test_empty_inputs_are_errors() -> None:
    """An empty baseline or an empty path cannot be compared: typed errors say which."""
    with pytest.raises(InputError, match="polyline has no vertex"):
        path_deviations(np.empty((0, 3)), [np.zeros((2, 3))])
    with pytest.raises(InputError, match="Path 1 has no position"):
        path_deviations(np.zeros((2, 3)), [np.ones((1, 3)), np.empty((0, 3))])


def test_finite_positions_drops_rows_with_nan() -> None:
    """Rows with a NaN or an infinity anywhere are left out; the others keep their order."""
    xyz = np.array([[0.0, 1.0, 2.0], [np.nan, 0.0, 0.0], [3.0, np.inf, 0.0], [4.0, 5.0, 6.0]])
    np.testing.assert_array_equal(finite_positions(xyz), [[0.0, 1.0, 2.0], [4.0, 5.0, 6.0]])
    assert PathDeviation(1, 0.0, 0.0).points == 1
