"""Tracking loss judged against each source's own rate (loceval.core.gaps)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from loceval.core.gaps import (
    GAP_RATE_FACTOR,
    gap_threshold_ns,
    loss_indices,
    path_breaks,
    tracking_losses,
)
from loceval.evaluation import evaluate
from loceval.readers import read_trajectory
from loceval.registration.association import associate
from loceval.trajectory import Trajectory
from tests.loceval.conftest import T0_NS

NS = 1_000_000_000


def _stamps(intervals_s: list[float]) -> np.ndarray:
    return T0_NS + np.rint(np.concatenate([[0.0], np.cumsum(intervals_s)]) * NS).astype(np.int64)


def test_threshold_is_five_median_intervals_above_the_floor() -> None:
    """At 1.5 Hz the threshold is 5 x 0.667 s; at 100 Hz the 0.1 s floor holds."""
    slow = _stamps([2 / 3] * 20)
    fast = _stamps([0.01] * 20)
    assert GAP_RATE_FACTOR == 5
    assert gap_threshold_ns(slow, min_gap_ns=NS // 10) == pytest.approx(10 / 3 * NS, abs=10)
    assert gap_threshold_ns(fast, min_gap_ns=NS // 10) == NS // 10
    assert gap_threshold_ns(slow[:1], min_gap_ns=NS // 10) == NS // 10


def test_losses_are_the_intervals_over_the_threshold() -> None:
    """A 1.5 Hz source with one 9 s silence has one loss, not an interval-per-gap."""
    stamps = _stamps([0.6] * 10 + [9.0] + [0.6] * 10 + [2.9])
    np.testing.assert_array_equal(loss_indices(stamps, min_gap_ns=NS // 10), [10])
    assert tracking_losses(stamps, min_gap_ns=NS // 10) == [(int(stamps[10]), int(stamps[11]))]
    assert tracking_losses(stamps[:1], min_gap_ns=NS // 10) == []


def test_trajectory_tracking_losses_delegates() -> None:
    """Trajectory.tracking_losses is the core rule; Trajectory.gaps stays the fixed rule."""
    stamps = _stamps([0.6] * 10 + [9.0] + [0.6] * 10)
    traj = Trajectory(stamps, np.zeros((stamps.shape[0], 3)), name="amcl")
    assert traj.tracking_losses(NS // 10) == [(int(stamps[10]), int(stamps[11]))]
    assert len(traj.gaps(NS // 10)) == 21


def test_interpolation_bridges_a_slow_reference() -> None:
    """A 1.5 Hz reference is interpolated between its poses, but not across its 9 s loss."""
    ref_stamps = _stamps([0.6] * 10 + [9.0] + [0.6] * 10)
    x = (ref_stamps - T0_NS) / NS
    ref = Trajectory(ref_stamps, np.stack([x, 0 * x, 0 * x], 1), name="amcl")
    est_stamps = np.arange(ref_stamps[0], ref_stamps[-1], NS // 10, dtype=np.int64)
    xe = (est_stamps - T0_NS) / NS
    est = Trajectory(est_stamps, np.stack([xe, 0 * xe, 0 * xe], 1), name="odom")
    matched = associate(ref, est, max_gap_ns=NS // 10)
    # 6.0 s to 15.0 s is the loss: the 89 stamps strictly inside it (6.1 ... 14.9) drop.
    assert matched.dropped_gap == 89
    assert len(matched) == len(est) - 89
    assert matched.max_gap_ns == 3 * NS
    np.testing.assert_allclose(matched.reference.positions_xyz[:, 0], xe[matched.estimate_index])


@pytest.mark.public_data
def test_nav2_amcl_is_matched_and_has_one_loss(public_data: Path) -> None:
    """nav2_turtlebot: AMCL at about 1.5 Hz reports its one 9.3 s standstill, not 134 gaps."""
    ref = read_trajectory(f"{public_data / 'nav2_turtlebot.mcap'}@tf:map:base_link")
    amcl = read_trajectory(f"{public_data / 'nav2_turtlebot.mcap'}@/amcl_pose")
    result = evaluate(ref, [amcl])
    notes = result.estimates[0].warnings
    own = [n for n in notes if n.startswith("The estimate itself")]
    # 135 AMCL poses, median interval 0.6 s -> threshold 3 s; only the 9.30 s interval exceeds it.
    assert len(own) == 1
    assert "1 gap" in own[0]
    assert "longer than 3 s" in own[0]
    assert "9.3 s, starts 5.71 s before the reference's first pose" in own[0]
    # The reference (tf map -> odom -> base_link, 2502 poses at 36 ms) keeps its 3 real losses.
    assert len(result.to_dict()["reference"]["gaps"]) == 3  # type: ignore[index]
    # AMCL as the reference: the odometry is interpolated between AMCL's poses, not dropped.
    odom = read_trajectory(f"{public_data / 'nav2_turtlebot.mcap'}@/odom")
    matched = associate(amcl, odom)
    assert matched.dropped_gap < len(odom) // 10
    assert len(matched) > len(odom) // 2


@pytest.mark.public_data
def test_ros_example_gaps_follow_each_topic_rate(public_data: Path) -> None:
    """ROS_example.bag: S-PTAM at 7.7 Hz has no loss (was 5438 at 0.1 s); ORB-SLAM none."""
    bag = public_data / "ROS_example.bag"
    for topic in ("S-PTAM", "ORB-SLAM"):
        assert read_trajectory(f"{bag}@{topic}").tracking_losses(NS // 10) == []
    truth = read_trajectory(f"{bag}@groundtruth")
    # 12765 poses at 60 ms median; 87 intervals of 0.36 s or more are recording dropouts.
    assert len(truth.tracking_losses(NS // 10)) == 87


def test_path_breaks_at_own_and_reference_losses() -> None:
    """A path breaks after its own long interval and across each reference loss it spans."""
    stamps = _stamps([0.1] * 5 + [2.0] + [0.1] * 5)  # own loss after pose 5
    # a reference loss from 0.15 s to 0.25 s overlaps the intervals 0.1-0.2 s and 0.2-0.3 s
    reference_losses = [(T0_NS + NS * 15 // 100, T0_NS + NS * 25 // 100)]
    breaks = path_breaks(stamps, min_gap_ns=NS // 10, losses=reference_losses)
    np.testing.assert_array_equal(np.flatnonzero(breaks), [1, 2, 5])
    assert path_breaks(stamps[:1], min_gap_ns=NS // 10).shape == (0,)
