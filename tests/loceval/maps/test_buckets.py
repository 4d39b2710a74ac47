"""The plan's bucket table: the same distances as measuring every segment, faster.

Points near walls (through the table), far from every wall and outside the table (through
the KD-tree) are measured against a brute-force distance to every segment of a plan of
rooms with a slanted wall; within the table's reach the distances are exact, beyond it
never more than half the sample spacing too large.
"""

from __future__ import annotations

import numpy as np

from loceval.maps.buckets import SegmentBuckets
from loceval.maps.plan import PlanIndex
from tests.mapfactory import office_plan


def _brute(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Distance of each point to the nearest of every segment (N x K; small cases only)."""
    a, b = segments[:, 0], segments[:, 1]
    ab = b - a
    t = np.einsum("nkj,kj->nk", points[:, None, :] - a[None], ab) / np.einsum("kj,kj->k", ab, ab)
    foot = a[None] + np.clip(t, 0.0, 1.0)[..., None] * ab[None]
    return np.linalg.norm(points[:, None, :] - foot, axis=2).min(axis=1)


def test_the_table_gives_the_brute_force_distances() -> None:
    """Near walls: exact; far away and outside: within half the sample spacing."""
    plan = np.concatenate([office_plan(), [[[1.0, 1.0], [7.5, 10.0]]]])  # and a slanted wall
    index = PlanIndex.build(plan, spacing_m=0.05)
    assert index.buckets is not None
    rng = np.random.default_rng(9)
    ends = plan.reshape(-1, 2)
    near = ends[rng.integers(0, len(ends), 3000)] + rng.normal(0.0, 0.4, (3000, 2))
    anywhere = rng.uniform(ends.min(axis=0) - 8.0, ends.max(axis=0) + 8.0, (3000, 2))
    points = np.concatenate([near, anywhere])
    found, closest = index.nearest(points)
    truth = _brute(points, index.segments_xy)
    within = truth <= index.buckets.reach_m
    np.testing.assert_allclose(found[within], truth[within], atol=1e-12)
    assert (found >= truth - 1e-12).all()
    assert (found - truth <= index.spacing_m / 2 + 1e-12).all()
    np.testing.assert_allclose(np.linalg.norm(points - closest, axis=1), found, atol=1e-12)
    # both paths were taken: some points through the table, some through the tree
    _, listed = index.buckets.lookup(points)
    assert listed.any()
    assert (~listed).any()


def test_a_plan_too_large_for_a_table_keeps_the_tree() -> None:
    """A plan spread over 20 km would need a table too large: None, and the tree answers."""
    plan = np.array([[[0.0, 0.0], [1.0, 0.0]], [[20_000.0, 20_000.0], [20_001.0, 20_000.0]]])
    assert SegmentBuckets.build(plan, size_m=1.0, reach_m=1.0) is None
    index = PlanIndex.build(plan, spacing_m=0.05)
    assert index.buckets is None
    distance, _ = index.nearest(np.array([[0.5, 0.3], [20_000.5, 19_999.0]]))
    np.testing.assert_allclose(distance, [0.3, 1.0])
