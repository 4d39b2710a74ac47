"""Stretches beyond the tolerance, the rooms they lie in, and the building's extent check.

Reference figures come from plain loops over the poses written here (the slow, obvious
way), against the core's vectorised code.
"""

from __future__ import annotations

import numpy as np
import pytest

from loceval.assessment.spaces import (
    Building,
    Space,
    check_building_extent,
    locate_in_spaces,
    locate_verdict,
)
from loceval.assessment.verdict import Tolerance, failing_spans, tolerance_verdict_of
from loceval.metrics.pose_errors import ErrorSeries
from loceval.trajectory import Trajectory

L_ROOM = [(0, 0), (6, 0), (6, 2), (2, 2), (2, 5), (0, 5)]
"""An L-shaped room: the crossing-number test must not take its hull."""


def _walk(rng: np.random.Generator, n: int = 5000) -> Trajectory:
    stamps = 1_000_000_000 + np.arange(n, dtype=np.int64) * 20_000_000  # 50 Hz
    xy = np.cumsum(rng.normal(0, 0.05, (n, 2)), axis=0) + 3.0
    return Trajectory(stamps, np.column_stack([xy, np.full(n, 1.3)]), name="truth")


def _loop_spans(values: np.ndarray, breaks: np.ndarray, tol: float) -> list[tuple[int, int]]:
    """(first, last) of each run of values > tol, cut at breaks: one pose at a time."""
    out: list[tuple[int, int]] = []
    start = None
    for i, v in enumerate(values):
        cut = i > 0 and bool(breaks[i - 1])
        if v > tol and (start is None or cut):
            if start is not None:
                out.append((start, i - 1))
            start = i
        elif v <= tol and start is not None:
            out.append((start, i - 1))
            start = None
    if start is not None:
        out.append((start, len(values) - 1))
    return out


def test_stretches_match_a_loop_over_poses(rng: np.random.Generator) -> None:
    """Runs, breaks, worst errors, lengths and order equal a pose-by-pose loop's."""
    truth = _walk(rng)
    n = len(truth)
    values = np.abs(np.sin(np.arange(n) / 37.0)) * 0.05 + rng.normal(0, 0.002, n)
    values[1200:1300] = 0.08  # a plateau: its worst is its first pose
    breaks = np.zeros(n - 1, dtype=bool)
    breaks[[1250, 3000, 4100]] = True  # tracking losses, one inside the plateau
    series = ErrorSeries(values, truth.stamps_ns, "m")
    t0 = int(truth.stamps_ns[0]) - 500_000_000
    spans = failing_spans(series, truth, 0.03, t0, breaks=breaks)
    expected = _loop_spans(values, breaks, 0.03)
    assert sorted((s.first_index, s.last_index) for s in spans) == sorted(expected)
    steps = np.linalg.norm(np.diff(truth.positions_xyz, axis=0), axis=1)
    for s in spans:
        a, b = s.first_index, s.last_index
        k = a + int(np.argmax(values[a : b + 1]))
        assert s.max_error_index == k
        assert s.max_error_m == values[k]
        assert s.poses == b - a + 1
        assert s.length_m == pytest.approx(float(steps[a:b].sum()), abs=1e-9)
        assert s.start_s == pytest.approx((truth.stamps_ns[a] - t0) / 1e9)
        assert s.duration_s == pytest.approx((truth.stamps_ns[b] - truth.stamps_ns[a]) / 1e9)
    assert [s.max_error_m for s in spans] == sorted((s.max_error_m for s in spans), reverse=True)
    # the break inside the plateau cuts it: one stretch ends at 1250, the next starts at 1251
    assert any(s.last_index == 1250 for s in spans)
    assert any(s.first_index == 1251 for s in spans)


def test_no_stretch_within_the_tolerance(rng: np.random.Generator) -> None:
    """An error equal to the tolerance is within it: no stretch, and the verdict has none."""
    truth = _walk(rng, 200)
    series = ErrorSeries(np.full(200, 0.03), truth.stamps_ns, "m")
    assert failing_spans(series, truth, 0.03, 0) == ()
    verdict = tolerance_verdict_of(series, truth, Tolerance(0.03, 0.95), 0, None)
    assert verdict.failing_spans == ()
    assert verdict.result == "pass"


def test_locate_l_shaped_nested_and_storeys() -> None:
    """Inside the L but not its hull; a zone inside a hall wins; heights pick the storey."""
    l_room = Space("L", L_ROOM, floor_m=0.0, ceiling_m=3.0)
    hall = Space("hall", [(10, 0), (20, 0), (20, 10), (10, 10)], floor_m=0.0, ceiling_m=3.0)
    zone = Space("zone", [(12, 2), (14, 2), (14, 4), (12, 4)], floor_m=0.0, ceiling_m=3.0)
    upstairs = Space("upstairs", [(10, 0), (20, 0), (20, 10), (10, 10)], 3.2, 6.0)
    points = np.array(
        [
            [1.0, 4.0, 1.2],  # in the L's arm
            [4.0, 4.0, 1.2],  # in the L's hull, not in the L
            [13.0, 3.0, 1.2],  # in the zone, inside the hall
            [18.0, 8.0, 1.2],  # in the hall
            [18.0, 8.0, 4.5],  # upstairs
            [18.0, 8.0, 9.0],  # above everything
        ]
    )
    spaces = [l_room, hall, zone, upstairs]
    assert locate_in_spaces(points, spaces).tolist() == [0, -1, 2, 1, 3, -1]
    assert l_room.area_m2 == pytest.approx(6 * 2 + 2 * 3)


def test_locate_matches_a_point_by_point_test(rng: np.random.Generator) -> None:
    """10,000 random points against the L: the vectorised test equals a per-point one."""
    points = np.column_stack(
        [rng.uniform(-1, 7, 10_000), rng.uniform(-1, 6, 10_000), np.zeros(10_000)]
    )
    got = locate_in_spaces(points, [Space("L", L_ROOM)]) == 0

    def inside(x: float, y: float) -> bool:  # the L as two rectangles
        return (0 <= x <= 6 and 0 <= y <= 2) or (0 <= x <= 2 and 0 <= y <= 5)

    expected = np.array([inside(x, y) for x, y, _ in points])
    edge = (np.abs(points[:, :2] - np.round(points[:, :2])) < 1e-9).any(axis=1)
    np.testing.assert_array_equal(got[~edge], expected[~edge])


def test_a_stretch_takes_the_room_of_most_of_its_poses() -> None:
    """Three poses in A and seven in B: B; none in a room: None."""
    n = 30
    stamps = np.arange(n, dtype=np.int64) * 100_000_000
    x = np.concatenate([np.linspace(1, 3.5, 13), np.linspace(4.5, 7, 7), np.full(10, 50.0)])
    truth = Trajectory(stamps, np.column_stack([x, np.full(n, 1.0), np.full(n, 1.0)]))
    values = np.zeros(n)
    values[10:20] = 0.1  # poses 10-12 in A (x < 4), 13-19 in B
    values[25:28] = 0.2  # far outside both
    verdict = tolerance_verdict_of(
        ErrorSeries(values, stamps, "m"), truth, Tolerance(0.05, 0.95), 0, None
    )
    building = Building(
        "plan.dxf",
        (
            Space("A", [(0, 0), (4, 0), (4, 2), (0, 2)]),
            Space("B", [(4, 0), (8, 0), (8, 2), (4, 2)]),
        ),
    )
    located = locate_verdict(verdict, truth.positions_xyz, building)
    assert [(s.first_index, s.space) for s in located.failing_spans] == [(25, None), (10, "B")]
    assert located.failing_spans[1].words(0.05) == "beyond 0.05 m for 0.9 s in B"
    assert verdict.failing_spans[1].space is None  # the input is unchanged


def test_building_extent_names_the_up_axis_to_set() -> None:
    """Paths outside the Y reading but inside the Z one: set z; outside both: check the site."""
    z_up = np.array([[0.0, 0.0, 0.0], [10.0, 6.0, 3.0]])
    y_up = np.array([[0.0, -3.0, 0.0], [10.0, 0.0, 6.0]])  # the same boxes read Y up
    truth = np.array([[2.0, 2.0, 1.2], [8.0, 4.0, 1.2]])
    bounds = {"z": z_up, "y": y_up}
    (warning,) = check_building_extent(bounds, "y", truth, source="office.glb", option="up")
    assert "set up to z" in warning
    assert check_building_extent(bounds, "z", truth, source="office.glb") == ()
    far = truth + 100.0
    (outside,) = check_building_extent(bounds, "z", far, source="office.glb")
    assert outside.startswith("The paths lie outside the building model 'office.glb'")
    # a 3 m x 3 m x 12 m column read Z up, a 3 m x 12 m x 3 m slab read Y up; the path
    # at y = 0 lies inside both: the reading that stands far taller than wide is questioned
    tall = {
        "z": np.array([[0.0, 0.0, 0.0], [3.0, 3.0, 12.0]]),
        "y": np.array([[0.0, -12.0, 0.0], [3.0, 0.0, 3.0]]),
    }
    inside_both = np.array([[1.0, 0.0, 1.0]])
    (lying,) = check_building_extent(tall, "z", inside_both, source="tower.glb", option="up")
    assert "far taller than wide" in lying
    assert "set up to y" in lying
    assert check_building_extent(tall, "y", inside_both, source="tower.glb") == ()
