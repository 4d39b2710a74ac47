"""The map against the plan, on generated cases whose truth is known.

Each case draws a plan's walls into a grid after a known plan -> map distortion; the
figures are compared with the truth computed here independently (exact point-to-segment
distances by brute force, the known inverse transform), within a tenth of a cell.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from loceval.core.geometry import SimilarityTransform
from loceval.core.polyline import segment_distances
from loceval.errors import InputError, MetricError
from loceval.maps import FREE, OCCUPIED, OccupancyGrid, evaluate_map
from tests.mapfactory import Distortion, draw_map, office_plan

RES = 0.05
TENTH = RES / 10
CLUTTER_XY = np.array([[3.0, 8.0], [12.5, 9.5], [7.0, 2.5]])


def plan_distances(points: np.ndarray, plan: np.ndarray) -> np.ndarray:
    """Exact distance of each point to the nearest plan segment (brute force, the truth)."""
    p = np.column_stack([points, np.zeros(len(points))])[:, None, :]
    a = np.column_stack([plan[:, 0], np.zeros(len(plan))])[None]
    b = np.column_stack([plan[:, 1], np.zeros(len(plan))])[None]
    return segment_distances(p, a, b).min(axis=1)


def true_figures(d: np.ndarray) -> dict[str, float]:
    """RMSE, mean, median, p95 and max of distances."""
    return {
        "rmse": float(np.sqrt(np.mean(d * d))),
        "mean": float(d.mean()),
        "median": float(np.median(d)),
        "p95": float(np.quantile(d, 0.95)),
        "max": float(d.max()),
    }


def assert_figures(found: object, truth: dict[str, float], tol: float) -> None:
    """Every figure within ``tol`` of the truth."""
    for key, value in truth.items():
        assert getattr(found, key) == pytest.approx(value, abs=tol), key


@pytest.fixture(scope="module", name="case")
def _case() -> tuple[np.ndarray, Distortion, OccupancyGrid]:
    """A map 1.2 % short, turned 2° and shifted, with noise and three clutter blobs."""
    rng = np.random.default_rng(20240601)
    plan = office_plan()
    distortion = Distortion(scale=0.988, yaw_deg=2.0, translation=(0.3, -0.2))
    grid = draw_map(
        plan, distortion, resolution_m=RES, rng=rng, noise_m=0.004, clutter_xy=CLUTTER_XY
    )
    return plan, distortion, grid


class TestScaledMap:
    """A map 1.2 % short, turned 2° and shifted, with noise and three clutter blobs."""

    def test_similarity_fit_is_the_inverse_distortion(self, case) -> None:
        """The similarity fit carries every map point onto its plan point within a tenth cell."""
        plan, distortion, grid = case
        result = evaluate_map(grid, plan, SimilarityTransform.identity())
        fit = result.similarity[0]
        corners = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 12.0], [0.0, 12.0], [10.0, 6.0]])
        moved = fit.apply(distortion.apply(corners))
        assert np.abs(moved - corners).max() < TENTH
        # a scale error moves points by itself times their distance from the centre (10 m)
        assert fit.scale == pytest.approx(1 / 0.988, abs=TENTH / 10.0)
        assert result.scale_error_pct == pytest.approx(-1.2, abs=0.05)
        assert result.drift_sentence() == "the map is 1.2 % short"

    def test_clutter_is_counted_and_left_out(self, case) -> None:
        """Clutter cells are exactly the blobs' wall cells, and no wall figure counts them."""
        plan, distortion, grid = case
        result = evaluate_map(grid, plan, SimilarityTransform.identity())
        rows, cols = np.nonzero(grid.wall_mask())
        in_plan = distortion.unapply(grid.cell_centres(rows, cols))
        near_blob = (np.abs(in_plan[:, None, :] - CLUTTER_XY[None]) <= 0.2 + RES).all(axis=2)
        assert result.clutter_cells == int(near_blob.any(axis=1).sum())
        assert result.clutter_cells > 3 * 20
        assert result.placed.n == len(rows) - result.clutter_cells
        assert result.to_dict()["clutter_cells"] == result.clutter_cells

    def test_figures_equal_the_truth(self, case) -> None:
        """Figures as placed and after the similarity fit equal the brute-force truth."""
        plan, distortion, grid = case
        result = evaluate_map(grid, plan, SimilarityTransform.identity())
        cells = result.cells_xy[~result.clutter]
        assert_figures(result.placed, true_figures(plan_distances(cells, plan)), TENTH)
        fitted = result.similarity[1]
        truth = true_figures(plan_distances(distortion.unapply(cells), plan))
        assert_figures(fitted, truth, TENTH)
        assert fitted.rmse < 0.02  # a cell's quantisation and the noise, nothing more
        assert fitted.plan_coverage is not None
        assert fitted.plan_coverage > 0.97
        for threshold, share in fitted.within.items():
            expected = np.mean(plan_distances(distortion.unapply(cells), plan) <= threshold)
            assert share == pytest.approx(expected, abs=0.01)

    def test_the_document_has_the_issue_fields(self, case) -> None:
        """map: wall_distance_m, within, plan_coverage, clutter_cells and fit{rigid,similarity}."""
        plan, _, grid = case
        doc = evaluate_map(grid, plan, SimilarityTransform.identity()).to_dict()
        assert set(doc["wall_distance_m"]) == {"rmse", "mean", "median", "p95", "max", "n"}
        assert set(doc["within"]) == {"0.05", "0.1", "0.15"}
        assert 0.0 <= doc["plan_coverage"] <= 1.0
        for name in ("rigid", "similarity"):
            fit = doc["fit"][name]
            assert {"scale", "rotation_deg", "translation_m", "wall_distance_m", "within"} <= set(
                fit
            )
        assert doc["fit"]["rigid"]["scale"] == 1.0
        assert doc["fit"]["similarity"]["rotation_deg"] == pytest.approx(-2.0, abs=0.02)


def test_a_map_placed_wrong_is_right_after_the_rigid_fit(rng) -> None:
    """A true map shifted 0.8 m and turned 3°: bad as placed, a cell's error after the fit."""
    plan = office_plan()
    grid = draw_map(
        plan, Distortion(yaw_deg=3.0, translation=(0.8, -0.5)), resolution_m=RES, rng=rng
    )
    result = evaluate_map(grid, plan, SimilarityTransform.identity())
    fit, figures = result.rigid
    assert result.placed.rmse > 0.3
    assert figures.rmse < RES / 2
    assert math.degrees(fit.rotation_rad) == pytest.approx(-3.0, abs=0.02)
    corners = np.array([[0.0, 0.0], [20.0, 12.0]])
    moved = fit.apply(Distortion(yaw_deg=3.0, translation=(0.8, -0.5)).apply(corners))
    assert np.abs(moved - corners).max() < TENTH
    assert result.similarity[0].scale == pytest.approx(1.0, abs=5e-4)


def test_a_bent_map_shows_its_bend_in_the_figures_and_the_regions(rng) -> None:
    """A 60 m corridor bent by 1° half way (the paper's Fig. 4): figures equal the truth."""
    plan = np.array(
        [[[0, 0], [60, 0]], [[0, 2.5], [60, 2.5]], [[0, 0], [0, 2.5]], [[60, 0], [60, 2.5]]],
        dtype=float,
    )
    bend = Distortion(bend_x_m=30.0, bend_deg=1.0)
    grid = draw_map(plan, bend, resolution_m=RES, rng=rng)
    result = evaluate_map(grid, plan, SimilarityTransform.identity(), clutter_m=2.0)
    # the truth: the bent walls, sampled densely, measured exactly against the plan
    t = np.linspace(0.0, 1.0, 6001)[:, None]
    long_walls = np.concatenate([a + t * (b - a) for a, b in plan[:2]])
    bent = bend.apply(long_walls)
    true_d = plan_distances(bent[np.abs(bent[:, 0] - 30.0) < 29.0], plan)
    assert result.placed.max == pytest.approx(30 * math.sin(math.radians(1.0)), abs=RES / 2)
    on_long = np.abs(result.cells_xy[:, 0] - 30.0) < 29.0  # the long walls, not the ends
    found = result.distance_m[on_long & ~result.clutter]
    assert float(np.sqrt(np.mean(found**2))) == pytest.approx(
        float(np.sqrt(np.mean(true_d**2))), abs=TENTH
    )
    # the mean of cell distances carries the cells' quantisation where the bend is under a
    # cell (|d + u| >= |d|), so it is compared with the cells' own exact distances
    cells = result.cells_xy[on_long & ~result.clutter]
    assert float(found.mean()) == pytest.approx(
        float(plan_distances(cells, plan).mean()), abs=TENTH
    )
    assert result.rigid[1].rmse > 0.05  # no rigid motion straightens a bend
    assert result.similarity[1].rmse > 0.05
    tiles = {(r["x_m"], r["y_m"]): r["rmse_m"] for r in result.regions}
    assert tiles[(57.5, 2.5)] > 0.4
    assert tiles[(2.5, 2.5)] < 0.03


def test_the_placement_carries_the_map_onto_the_plan(rng) -> None:
    """A map in another frame placed by the estimate's alignment lands on the plan."""
    plan = office_plan()
    grid = draw_map(
        plan, Distortion(yaw_deg=90.0, translation=(5.01, 1.01)), resolution_m=RES, rng=rng
    )
    a = math.radians(-90.0)
    rotation = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    back = SimilarityTransform(rotation, rotation @ -np.array([5.01, 1.01, 0.0]))
    result = evaluate_map(grid, plan, back, estimate="SLAM")
    assert result.placed.rmse < RES / 2
    assert result.to_dict()["placed_by"]["estimate"] == "SLAM"


def test_a_map_without_occupied_cells_is_refused() -> None:
    """No occupied cell: InputError naming the thresholds."""
    grid = OccupancyGrid(np.full((20, 20), FREE, dtype=np.int8), RES, source="empty.yaml")
    with pytest.raises(InputError, match=r"no occupied cell.*occupied_thresh"):
        evaluate_map(grid, office_plan(), SimilarityTransform.identity())


def test_a_map_whose_occupied_cells_see_no_free_space_is_refused() -> None:
    """Occupied cells only next to unknown ones: no wall the robot saw."""
    states = np.full((20, 20), -1, dtype=np.int8)
    states[5:8, 5:8] = OCCUPIED
    grid = OccupancyGrid(states, RES, source="dark.yaml")
    with pytest.raises(InputError, match="none next to free space"):
        evaluate_map(grid, office_plan(), SimilarityTransform.identity())


def test_a_map_and_a_plan_without_overlap_are_refused(rng) -> None:
    """A map 100 m away from the plan: MetricError saying they do not overlap."""
    plan = office_plan()
    grid = draw_map(plan, Distortion(translation=(100.0, 0.0)), resolution_m=RES, rng=rng)
    with pytest.raises(MetricError, match="do not overlap"):
        evaluate_map(grid, plan, SimilarityTransform.identity())


def test_a_map_near_but_not_on_the_plan_is_refused(rng) -> None:
    """Map walls inside the plan's extent but nowhere near its walls: too few to fit."""
    plan = np.array([[[0, 0], [40, 0]], [[0, 40], [40, 40]]], dtype=float)
    small = np.array(
        [[[15, 15], [25, 15]], [[15, 25], [25, 25]], [[15, 15], [15, 25]]], dtype=float
    )
    grid = draw_map(small, Distortion(), resolution_m=RES, rng=rng)
    with pytest.raises(MetricError, match="overlap"):
        evaluate_map(grid, plan, SimilarityTransform.identity())
