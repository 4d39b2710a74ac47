"""Per-axis scale: a map stretched differently along its two axes, recovered.

The plan is the office of :func:`tests.mapfactory.office_plan` (20 m x 12 m, rooms); the
map is drawn from that plan stretched by 1.02 along x and 0.99 along y, in 2 cm cells
(noise-free, so the error left is the cells' quantisation). The truth is recovered within
a tenth of a cell at the plan's far edge: |Δs_x| x 10 m and |Δs_y| x 6 m under 2 mm
(measured: 1/s_x = 1.020000, 1/s_y = 0.989914: 0.0 mm and 0.5 mm at the edge). The
Gauss-Newton sigmas (measured 7.7e-6 and 1.0e-5) are a lower bound: the quantisation's
error is systematic per wall, not independent per cell (s_y is off by 8 of them).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from loceval.core.geometry import SimilarityTransform
from loceval.maps import OccupancyGrid, evaluate_map
from tests.mapfactory import Distortion, draw_map, office_plan

RESOLUTION_M = 0.02
STRETCH = (1.02, 0.99)


def _stretched_map() -> tuple[np.ndarray, OccupancyGrid]:
    """The plan, and a map of it stretched along x and y."""
    plan = office_plan()
    centre = plan.reshape(-1, 2).mean(axis=0)
    stretched = (plan - centre) * np.array(STRETCH) + centre
    grid = draw_map(
        stretched,
        Distortion(),
        resolution_m=RESOLUTION_M,
        rng=np.random.default_rng(4),
    )
    return plan, grid


def test_a_map_stretched_per_axis_is_recovered() -> None:
    """1.02 along x, 0.99 along y: the lengths come back within a tenth of a cell at the edge."""
    plan, grid = _stretched_map()
    found = evaluate_map(grid, plan, SimilarityTransform.identity())
    scales = found.axis_scales
    assert scales is not None
    half = np.ptp(plan.reshape(-1, 2), axis=0) / 2.0  # 10 m, 6 m
    assert abs(1.0 / scales.scale_x - STRETCH[0]) * half[0] < RESOLUTION_M / 10
    assert abs(1.0 / scales.scale_y - STRETCH[1]) * half[1] < RESOLUTION_M / 10
    assert scales.length_error_x_pct == pytest.approx(2.0, abs=0.02)
    assert scales.length_error_y_pct == pytest.approx(-1.0, abs=0.02)
    # the uncertainty is small and positive (a lower bound, see the module docstring)
    assert scales.sigma_x is not None
    assert 0.0 < scales.sigma_x < 1e-3
    assert scales.sigma_y is not None
    assert 0.0 < scales.sigma_y < 1e-3
    # the similarity fit's one scale lies between the two
    assert scales.scale_x < found.similarity[0].scale < scales.scale_y
    doc = found.to_dict()["axis_scales"]  # type: ignore[index]
    assert doc["length_error_x_pct"] == scales.length_error_x_pct  # type: ignore[index]
    assert doc["axes_deg"] == pytest.approx(0.0, abs=1e-9)  # type: ignore[index]


def test_the_scales_follow_the_map_axes_not_the_plan_axes() -> None:
    """The plan turned 30° and the map placed by that turn: the stretch stays on the map's axes.

    The map's x axis then runs at 30° on the plan; the fit reports 1.02 along it and 0.99
    across it (the plan's own x and y would mix the two).
    """
    plan, grid = _stretched_map()
    turn = math.radians(30.0)
    rotation = np.array([[math.cos(turn), -math.sin(turn)], [math.sin(turn), math.cos(turn)]])
    matrix = np.eye(4)
    matrix[:2, :2] = rotation
    placement = SimilarityTransform.from_matrix(matrix)
    found = evaluate_map(grid, plan @ rotation.T, placement)
    scales = found.axis_scales
    assert scales is not None
    assert scales.axes_deg == pytest.approx(30.0, abs=0.01)
    assert scales.length_error_x_pct == pytest.approx(2.0, abs=0.02)
    assert scales.length_error_y_pct == pytest.approx(-1.0, abs=0.02)


def test_a_corridor_leaves_its_length_scale_unobservable() -> None:
    """Two parallel walls: nothing fixes the length along them, so no per-axis figure."""
    plan = np.array([[[0.0, 0.0], [30.0, 0.0]], [[0.0, 2.0], [30.0, 2.0]]])
    grid = draw_map(plan, Distortion(scale=0.99), resolution_m=0.05, rng=np.random.default_rng(6))
    found = evaluate_map(grid, plan, SimilarityTransform.identity())
    assert found.axis_scales is None
    assert found.to_dict()["axis_scales"] is None  # type: ignore[index]
