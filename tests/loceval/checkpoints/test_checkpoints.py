"""Control points: visits found or given, robust alignment, per-visit errors and scores."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from loceval.checkpoints.fit import evaluate_checkpoints, fit_points
from loceval.checkpoints.scores import hilti_score, lamaria_score
from loceval.checkpoints.stops import find_stops
from loceval.controlpoints import ControlPoints, Visits
from loceval.errors import AlignmentError, InputError
from loceval.readers.points import read_visits
from loceval.registration.alignment import AlignMethod
from loceval.trajectory import Trajectory
from tests.checkpoint_factory import NS, grid_points, stop_and_go, write_visits


def _truth_errors(rec, transform=None) -> np.ndarray:
    """Independent per-visit errors: a loop over the true visit windows."""
    out = []
    pos = rec.estimate.positions_xyz
    for pid, a, b in zip(rec.visit_ids, rec.visit_start_ns, rec.visit_end_ns, strict=True):
        inside = [k for k, s in enumerate(rec.estimate.stamps_ns) if a <= s <= b]
        median = np.array([np.median(pos[inside, axis]) for axis in range(3)])
        if transform is not None:
            median = transform(median)
        surveyed = rec.points.positions_xyz[rec.points.ids.index(pid)]
        out.append(median - surveyed)
    return np.array(out)


def _hilti_by_hand(errors: np.ndarray) -> float:
    total = 0
    for e in errors:
        for tier_m, points in ((0.005, 20), (0.01, 10), (0.03, 6), (0.06, 5), (0.10, 3), (0.40, 1)):
            if e < tier_m:
                total += points
                break
    return 100.0 * total / (20 * len(errors))


def _lamaria_by_hand(errors: np.ndarray) -> float:
    knots = [(0.05, 20), (0.2, 18), (0.5, 15), (1, 12), (2, 8), (5, 4), (10, 0)]
    total = 0.0
    for e in errors:
        if e <= knots[0][0]:
            total += 20
        elif e >= knots[-1][0]:
            total += 0
        else:
            for (x0, y0), (x1, y1) in itertools.pairwise(knots):
                if x0 <= e <= x1:
                    total += y0 + (y1 - y0) * (e - x0) / (x1 - x0)
                    break
    return 100.0 * total / (20 * len(errors))


def test_auto_visits_find_every_visit_and_its_point(rng):
    """A 5 x 9 grid visited three times: every stop is found and given the right point."""
    rec = stop_and_go(rng, grid_points())
    result = evaluate_checkpoints(rec.points, rec.estimate)
    assert [v.point_id for v in result.visits] == rec.visit_ids
    assert len(result.visits) == 135
    assert result.unmatched_stops == ()
    assert result.unvisited == ()
    errors = np.array([v.error_xyz for v in result.visits])
    np.testing.assert_allclose(errors, _truth_errors(rec), atol=1e-3)


def test_visits_file_gives_the_same_errors(rng, tmp_path):
    """With the true visit windows from a file the errors equal the loop's within 1 mm."""
    rec = stop_and_go(rng, grid_points())
    visits = read_visits(write_visits(tmp_path / "visits.csv", rec), rec.points)
    result = evaluate_checkpoints(rec.points, rec.estimate, visits=visits)
    errors = np.array([v.error_xyz for v in result.visits])
    np.testing.assert_allclose(errors, _truth_errors(rec), atol=1e-6)
    auto = evaluate_checkpoints(rec.points, rec.estimate)
    np.testing.assert_allclose(
        [v.error_m for v in auto.visits], [v.error_m for v in result.visits], atol=1e-3
    )


def test_scores_equal_a_hand_computation(rng):
    """Hilti and LaMAria scores equal a loop over the tiers and the piecewise curve."""
    rec = stop_and_go(rng, grid_points(), noise_m=0.01, bias_xyz=(0.02, 0.01, 0.0))
    doc = evaluate_checkpoints(rec.points, rec.estimate).to_dict()
    visits = doc["checkpoints"]["visits"]
    e3 = np.array([v["error_m"] for v in visits])
    eh = np.array([v["error_h_m"] for v in visits])
    assert doc["checkpoints"]["score"]["hilti"] == pytest.approx(_hilti_by_hand(e3), abs=1e-9)
    assert doc["checkpoints"]["score"]["lamaria"] == pytest.approx(_lamaria_by_hand(eh), abs=1e-9)
    assert doc["ate"]["translation_m"]["n"] == 135
    assert doc["ate"]["rotation_deg"] is None
    assert doc["checkpoints"]["recall"]["0.05"] == pytest.approx(
        np.mean(
            [
                min(e for v, e in zip(visits, e3, strict=True) if v["id"] == pid) <= 0.05
                for pid in rec.points.ids
            ]
        )
    )


def test_score_tiers_are_strict():
    """An error of exactly a tier's bound earns the next tier; beyond 40 cm earns nothing."""
    assert hilti_score(np.array([0.004])) == 100.0
    assert hilti_score(np.array([0.005])) == 50.0
    assert hilti_score(np.array([0.5])) == 0.0
    assert lamaria_score(np.array([0.01])) == 100.0
    assert lamaria_score(np.array([0.35])) == pytest.approx(100 * 16.5 / 20)
    assert lamaria_score(np.array([12.0])) == 0.0


def test_se3_alignment_with_points_left_out(rng, tmp_path):
    """A point left out of the alignment is scored, not fitted; alignment visits are marked."""
    R = Rotation.from_euler("xyz", [2, -1, 35], degrees=True).as_matrix()
    shift = np.array([12.0, -3.0, 0.4])
    rec = stop_and_go(rng, grid_points(), frame=(R, shift), bias_xyz=(0.0, 0.0, 0.0))
    visits = read_visits(write_visits(tmp_path / "v.csv", rec), rec.points)
    chosen = ["P00", "P08", "P40", "P48", "P24"]
    result = evaluate_checkpoints(
        rec.points, rec.estimate, visits=visits, method=AlignMethod.SE3, align_points=chosen
    )
    np.testing.assert_allclose(result.transform.rotation, R, atol=2e-3)
    np.testing.assert_allclose(result.transform.translation, shift, atol=5e-3)
    used = {v.point_id for v in result.visits if v.used_for_alignment}
    assert used == set(chosen)
    doc = result.to_dict()
    assert doc["ate"]["translation_m"]["n"] == 135 - 15
    assert all(v["used_for_alignment"] == (v["id"] in chosen) for v in doc["checkpoints"]["visits"])
    # The scored errors equal the independent computation with the fitted transform.
    truth = _truth_errors(rec, result.transform.apply_positions)
    scored = [k for k, pid in enumerate(rec.visit_ids) if pid not in chosen]
    np.testing.assert_allclose(
        [v.error_m for v in result.scored], np.linalg.norm(truth[scored], axis=1), atol=1e-3
    )


def test_an_outlying_point_moves_the_alignment_little(rng):
    """A control point surveyed 0.5 m off shifts the robust fit by less than 2 mm."""
    points = grid_points()
    dst = points.positions_xyz + rng.normal(0, 0.003, points.positions_xyz.shape)
    src = dst - [1.0, 2.0, 0.0]
    clean, _ = fit_points(src, dst, method=AlignMethod.SE3)
    bad = dst.copy()
    bad[7] += [0.5, 0.0, 0.0]
    robust, far = fit_points(src, bad, method=AlignMethod.SE3)
    moved = np.abs(robust.apply_positions(src) - clean.apply_positions(src)).max()
    assert moved < 0.002
    assert np.flatnonzero(far).tolist() == [7]
    from loceval.registration.alignment import align_umeyama

    plain = align_umeyama(src, bad)
    assert np.abs(plain.apply_positions(src) - clean.apply_positions(src)).max() > 5 * moved


def test_sigma_weights_the_alignment():
    """A point with a large survey sigma pulls the fit less than a precise one."""
    points = grid_points(3, 3, 1.0)
    dst = points.positions_xyz.copy()
    src = dst.copy()
    src[0] += [0.02, 0.0, 0.0]  # a small disagreement at the corner point
    sigma = np.full((9, 3), 0.001)
    loose = sigma.copy()
    loose[0] = 0.5
    tight, _ = fit_points(src, dst, method=AlignMethod.SE3, sigma_xyz=sigma)
    weak, _ = fit_points(src, dst, method=AlignMethod.SE3, sigma_xyz=loose)
    residual = lambda t: np.abs(t.apply_positions(src[1:]) - dst[1:]).max()  # noqa: E731
    assert residual(weak) < residual(tight)


def test_symmetric_grid_with_auto_visits_refuses_to_guess(rng):
    """Auto visits in another frame on a grid fit two ways: ask for a visits file."""
    R = Rotation.from_euler("z", 20, degrees=True).as_matrix()
    rec = stop_and_go(rng, grid_points(), frame=(R, np.array([5.0, 1.0, 0.0])))
    with pytest.raises(AlignmentError, match="symmetric layout") as info:
        evaluate_checkpoints(rec.points, rec.estimate, method=AlignMethod.SE3)
    assert info.value.option == "visits"


def test_asymmetric_layout_registers_auto_visits(rng):
    """Irregular survey points are found in another frame without a visits file."""
    xyz = np.column_stack([rng.uniform(0, 20, 12), rng.uniform(0, 8, 12), rng.uniform(0, 0.3, 12)])
    points = ControlPoints(tuple(f"S{k}" for k in range(12)), xyz)
    R = Rotation.from_euler("z", -70, degrees=True).as_matrix()
    shift = np.array([100.0, 50.0, 2.0])
    rec = stop_and_go(rng, points, passes=2, speed_mps=1.0, frame=(R, shift), bias_xyz=(0, 0, 0))
    result = evaluate_checkpoints(points, rec.estimate, method=AlignMethod.SE3)
    assert [v.point_id for v in result.visits] == rec.visit_ids
    np.testing.assert_allclose(result.transform.rotation, R, atol=1e-3)
    assert result.to_dict()["ate"]["translation_m"]["rmse"] < 0.01


def test_stationing_points_settle_a_symmetric_grid(rng):
    """Standing on the named alignment points first fixes the grid's placement."""
    points = grid_points()
    chosen = ["P00", "P08", "P44"]
    first = [points.ids.index(c) for c in chosen]
    rest = [k for k in rng.permutation(45).tolist() if k != first[-1]] + [first[-1]]
    order = first + rest  # no point twice in a row: that would be one stop
    R = Rotation.from_euler("z", 200, degrees=True).as_matrix()
    rec = stop_and_go(rng, points, order=order, frame=(R, np.array([3.0, 4.0, 0.0])))
    result = evaluate_checkpoints(points, rec.estimate, method=AlignMethod.SE3, align_points=chosen)
    assert [v.point_id for v in result.visits] == rec.visit_ids
    assert sum(v.used_for_alignment for v in result.visits) == 6  # stationing + one pass


def test_unmatched_stops_and_unvisited_points_are_listed(rng):
    """A stop away from every point is listed; a point never visited is listed."""
    points = grid_points(3, 3, 1.0)
    rec = stop_and_go(rng, points, order=[0, 1, 2, 3, 4, 5, 6, 7])
    t = rec.estimate.stamps_ns
    extra_t = t[-1] + np.arange(1, 150) * (NS // 30)
    extra = np.tile([[5.0, 5.0, 0.0]], (len(extra_t), 1))
    est = Trajectory(
        np.concatenate([t, extra_t]), np.vstack([rec.estimate.positions_xyz, extra]), None
    )
    doc = evaluate_checkpoints(points, est).to_dict()
    assert doc["checkpoints"]["unvisited"] == ["P22"]
    assert len(doc["checkpoints"]["unmatched_stops"]) == 1
    np.testing.assert_allclose(doc["checkpoints"]["unmatched_stops"][0]["position"], [5, 5, 0])
    assert doc["checkpoints"]["recall"]["0.05"] == pytest.approx(8 / 9)
    assert any("unmatched stops" in w for w in doc["warnings"])


def test_no_stationary_period_is_an_error():
    """An estimate that never stops cannot have automatic visits."""
    t = np.arange(0, 600) * (NS // 30)
    xyz = np.column_stack([np.arange(600) * 0.03, np.zeros(600), np.zeros(600)])
    with pytest.raises(InputError, match="No stationary period") as info:
        evaluate_checkpoints(grid_points(), Trajectory(t, xyz, None))
    assert info.value.option == "visits"


def test_visits_outside_the_estimate_are_an_error(rng):
    """Visits on another clock than the estimate's are refused with the range."""
    rec = stop_and_go(rng, grid_points(3, 3, 1.0), passes=1)
    visits = Visits(np.array([0, 1]), np.array([0, 10 * NS]), np.array([NS, 11 * NS]))
    with pytest.raises(InputError, match="outside the estimate's time range"):
        evaluate_checkpoints(rec.points, rec.estimate, visits=visits)


def test_unknown_alignment_point_is_an_error(rng):
    """An alignment point that is not surveyed is named."""
    rec = stop_and_go(rng, grid_points(3, 3, 1.0), passes=1)
    with pytest.raises(InputError, match="'Q9'"):
        evaluate_checkpoints(
            rec.points, rec.estimate, method=AlignMethod.SE3, align_points=["P00", "Q9"]
        )


def test_calibrate_alignment_is_refused_for_points(rng):
    """Control points have no orientation to calibrate on."""
    rec = stop_and_go(rng, grid_points(3, 3, 1.0), passes=1)
    with pytest.raises(InputError, match="none, se3, sim3 or yaw"):
        evaluate_checkpoints(rec.points, rec.estimate, method=AlignMethod.CALIBRATE)


def test_find_stops_ignores_noise_and_short_pauses(rng):
    """Standing still with 5 mm of noise is a stop; a 0.5 s pause is not."""
    rate = 30
    t = np.arange(0, 20 * rate) / rate
    x = np.interp(t, [0, 5, 8, 8.5, 12, 20], [0, 1.5, 1.5, 1.5, 3.0, 3.0])
    xyz = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    xyz += rng.normal(0, 0.005, xyz.shape)
    stops = find_stops(Trajectory(np.rint(t * NS).astype(np.int64), xyz, None))
    spans = [(s.start_ns / NS, s.end_ns / NS) for s in stops]
    assert len(spans) == 2
    assert spans[0][0] == pytest.approx(5.0, abs=0.4)
    assert spans[0][1] == pytest.approx(8.5, abs=0.4)
    assert spans[1][0] == pytest.approx(12.0, abs=0.4)
