"""The tables ``loceval evaluate`` prints: excursions, numbered poses, gaps (issue 44, 11, 15, 16).

Known geometry throughout: the excursion run of :mod:`tests.loceval.metrics.test_excursions`
(45 m walked outside, drifting 5 mm per metre: 0.225 m at re-entry), a reference of numbered
poses, and a reference recorded every 32.178 ms (gaps are intervals over five of them,
160.89 ms) with 18 gaps.
"""

from __future__ import annotations

import numpy as np
import pytest

from loceval.evaluation import EvaluationConfig, evaluate
from loceval.registration.alignment import AlignWindow
from loceval.trajectory import Trajectory
from service.cli.tables import format_tables
from tests.loceval.metrics.test_excursions import DRIFT_PER_M
from tests.loceval.metrics.test_excursions import _run as excursion_run

INTERVAL_NS = 32_178_000


def test_the_excursion_drift_is_a_share_of_the_distance_outside() -> None:
    """45 m outside, 0 m on leaving, 0.225 m back: 0.50 % of the 45 m (not of the whole path).

    On main the line read "45 s, 45 m: 0.23 m at re-entry after 0.00 m on leaving, 0.50 % of
    the path", which a reader took for a share of the run's whole path.
    """
    reference, estimate, path_m = excursion_run()
    config = EvaluationConfig(align_first=AlignWindow.parse("19s"), no_ci=True)
    text = format_tables(evaluate(reference, [estimate], config))
    (line,) = [line.strip() for line in text.splitlines() if "out of the room" in line]
    drift_pct = DRIFT_PER_M * 100
    assert line == (
        f"slam: out of the room for 45 s over {path_m:.1f} m: error 0.000 m on leaving → "
        f"{DRIFT_PER_M * path_m:.3f} m at re-entry, drift {drift_pct:.2f} % of the distance "
        "travelled outside"
    )
    assert path_m == pytest.approx(45.0, abs=0.1)


def test_numbered_poses_are_no_seconds() -> None:
    """A reference without times (KITTI without its times file): no duration in seconds."""
    rng = np.random.default_rng(7)
    xyz = np.cumsum(rng.normal(0.0, 0.1, (400, 3)), axis=0)
    stamps = np.arange(400, dtype=np.int64) * 1_000_000_000
    reference = Trajectory(stamps, xyz, None, name="gt", indexed=True)
    estimate = Trajectory(stamps, xyz + rng.normal(0.0, 0.01, xyz.shape), None, name="est")
    text = format_tables(evaluate(reference, [estimate], EvaluationConfig(no_ci=True)))
    head = text.splitlines()[0]
    assert head.startswith("Reference 'gt': 400 poses, no timestamps (poses numbered), ")
    assert "399.0 s" not in text


def test_gaps_are_written_with_sensible_digits() -> None:
    """18 gaps longer than five 32.178 ms intervals: "longer than 161 ms", not 0.16089 s."""
    rng = np.random.default_rng(3)
    steps = np.full(1200, INTERVAL_NS, dtype=np.int64)
    steps[np.arange(18) * 60 + 30] = 400_000_000  # 18 gaps of 0.4 s
    stamps = 1_000_000_000 + np.concatenate([[0], np.cumsum(steps)])
    xyz = np.cumsum(rng.normal(0.0, 0.01, (stamps.size, 3)), axis=0)
    reference = Trajectory(stamps, xyz, None, name="gt")
    estimate = Trajectory(stamps, xyz + 0.001, None, name="est")
    result = evaluate(reference, [estimate], EvaluationConfig(no_ci=True))
    (note,) = [w for w in result.reference_warnings if "gaps longer than" in w]
    assert "The reference has 18 gaps longer than 161 ms (tracking loss; longest 400 ms)" in note
    assert "0.16089" not in format_tables(result)
