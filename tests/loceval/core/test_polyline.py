"""Point-to-polyline distances and polyline simplification (loceval.core.polyline, the core).

Expected values come from an independent computation written here: the segments are
sampled densely (every ~0.1 mm) and the nearest sample is taken, so no projection formula
of the module under test is reused; closed-form cases are worked out by hand next to them.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from loceval.core import polyline
from loceval.core.polyline import (
    PolylineIndex,
    path_distances,
    polyline_distances,
    segment_distances,
    simplify_rdp,
    simplify_rdp_runs,
)
from loceval.errors import InputError


def sampled_distances(
    points: np.ndarray, vertices: np.ndarray, *, samples: int = 20_001
) -> np.ndarray:
    """Brute force without projection: the nearest of ``samples`` points on every segment."""
    best = np.full(len(points), np.inf)
    pairs = itertools.pairwise(vertices) if len(vertices) > 1 else [(vertices[0], vertices[0])]
    for a, b in pairs:  # test reference: a loop over the few segments is fine here
        on_segment = a + np.linspace(0.0, 1.0, samples)[:, None] * (b - a)
        gaps = np.linalg.norm(points[:, None, :] - on_segment[None], axis=2)
        best = np.minimum(best, gaps.min(axis=1))
    return best


def sampling_error(vertices: np.ndarray, samples: int = 20_001) -> float:
    """Largest gap between a segment point and its nearest sample: half the sample step."""
    lengths = np.linalg.norm(np.diff(vertices, axis=0), axis=1)
    return float(lengths.max(initial=0.0)) / (samples - 1) / 2.0 + 1e-12


class TestSegmentDistances:
    def test_closed_form_cases(self):
        """Beside, beyond either end, on, and a zero-length segment (hand-computed values)."""
        a = np.array([0.0, 0.0, 0.0])
        b = np.array([2.0, 0.0, 0.0])
        points = np.array(
            [
                [1.0, 3.0, 4.0],  # beside the middle: hypot(3, 4) = 5
                [5.0, 4.0, 0.0],  # beyond b: hypot(5 - 2, 4) = 5
                [-1.0, 0.0, 1.0],  # before a: hypot(1, 1) = sqrt(2)
                [0.5, 0.0, 0.0],  # on the segment: 0
            ]
        )
        np.testing.assert_allclose(
            segment_distances(points, a, b), [5.0, 5.0, np.sqrt(2.0), 0.0], atol=1e-15
        )
        np.testing.assert_allclose(segment_distances(points, a, a), np.linalg.norm(points, axis=1))

    def test_broadcasts_to_a_table(self, rng: np.random.Generator):
        """(N, 1, 3) points against (1, M, 3) segments give the (N, M) table of row-wise values."""
        points = rng.normal(size=(40, 3))
        starts, ends = rng.normal(size=(6, 3)), rng.normal(size=(6, 3))
        table = segment_distances(points[:, None, :], starts[None], ends[None])
        assert table.shape == (40, 6)
        for m in range(6):  # row-wise form, one segment at a time
            np.testing.assert_array_equal(
                table[:, m],
                segment_distances(points, np.tile(starts[m], (40, 1)), np.tile(ends[m], (40, 1))),
            )
            expected = sampled_distances(points, np.stack([starts[m], ends[m]]))
            np.testing.assert_allclose(
                table[:, m], expected, atol=sampling_error(np.stack([starts[m], ends[m]]))
            )


class TestPolylineDistances:
    def test_match_dense_sampling(self, rng: np.random.Generator):
        """Exact distances agree with the sampled brute force within its sampling error."""
        points = rng.normal(size=(60, 3))
        vertices = np.cumsum(rng.normal(scale=0.5, size=(7, 3)), axis=0)
        expected = sampled_distances(points, vertices)
        actual = polyline_distances(points, vertices)
        assert np.all(actual <= expected + 1e-12)  # the exact minimum is never above a sample
        np.testing.assert_allclose(actual, expected, atol=sampling_error(vertices))
        np.testing.assert_allclose(
            polyline_distances(points, vertices[:1]), np.linalg.norm(points - vertices[0], axis=1)
        )

    def test_blocks_do_not_change_the_result(
        self, rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch
    ):
        """Blocks of 7 pairs (3 points each against 2 segments) give the one-block answer."""
        points = rng.normal(size=(100, 3))
        vertices = rng.normal(size=(3, 3))
        whole = polyline_distances(points, vertices)
        monkeypatch.setattr(polyline, "_CHUNK_PAIRS", 7)
        np.testing.assert_array_equal(polyline_distances(points, vertices), whole)

    def test_no_vertex_is_an_error(self):
        """A polyline without a vertex has no distance: a typed error says so."""
        with pytest.raises(InputError, match="polyline has no vertex"):
            polyline_distances(np.zeros((2, 3)), np.empty((0, 3)))
        with pytest.raises(InputError, match="polyline has no vertex"):
            PolylineIndex.build(np.empty((0, 3)))


class TestPolylineIndex:
    def test_within_half_the_spacing_never_below(self, rng: np.random.Generator):
        """At 5 cm spacing the indexed distance is exact to 2.5 cm, and never below the truth."""
        s = np.linspace(0.0, 2 * np.pi, 400)
        vertices = np.stack([4.0 * np.cos(s), 3.0 * np.sin(s), 0.1 * np.sin(3 * s)], axis=1)
        points = np.vstack(
            [vertices + rng.normal(scale=0.05, size=vertices.shape), rng.uniform(-6, 6, (300, 3))]
        )
        index = PolylineIndex.build(vertices, spacing_m=0.05)
        assert index.spacing_m == 0.05
        fast = index.distances(points)
        exact = polyline_distances(points, vertices)
        assert np.all(fast >= exact - 1e-12)
        assert np.max(fast - exact) <= 0.025 + 1e-12

    def test_default_spacing_is_half_a_millimetre_exact(self, rng: np.random.Generator):
        """path_distances (1 mm spacing) is within 0.5 mm of the sampled brute force."""
        vertices = np.cumsum(rng.normal(scale=0.3, size=(12, 3)), axis=0)
        points = vertices[:-1] + rng.normal(scale=0.2, size=(11, 3))
        expected = sampled_distances(points, vertices)
        np.testing.assert_allclose(
            path_distances(points, vertices), expected, atol=0.0005 + sampling_error(vertices)
        )


class TestSimplify:
    def test_deviation_within_tolerance_and_reported_exactly(self, rng: np.random.Generator):
        """No original vertex is farther than the tolerance, and the reported maximum is true."""
        t = np.linspace(0, 6 * np.pi, 5000)
        points = np.stack([np.cos(t) * t, np.sin(t) * t, 0.1 * t], 1)
        points += rng.normal(0.0, 0.0005, points.shape)
        kept, deviation = simplify_rdp(points, 0.002)
        actual = polyline_distances(points, points[kept])
        assert 10 < len(kept) < len(points)
        assert deviation <= 0.002
        assert actual.max() <= deviation + 1e-12
        assert actual.max() == pytest.approx(deviation, abs=1e-12)

    def test_endpoints_zero_tolerance_and_lines(self):
        """Endpoints stay, tolerance 0 keeps all, a straight line keeps two vertices."""
        line = np.stack([np.arange(100.0), 2 * np.arange(100.0), np.zeros(100)], 1)
        kept, deviation = simplify_rdp(line, 1e-6)
        np.testing.assert_array_equal(kept, [0, 99])
        assert deviation < 1e-9
        kept0, deviation0 = simplify_rdp(line, 0.0)
        np.testing.assert_array_equal(kept0, np.arange(100))
        assert deviation0 == 0.0

    def test_closed_loop(self):
        """A loop whose first and last points coincide simplifies against segments, not lines."""
        s = np.linspace(0, 2 * np.pi, 2000)
        loop = np.stack([np.cos(s), np.sin(s), np.zeros_like(s)], 1)
        kept, deviation = simplify_rdp(loop, 0.001)
        assert 20 < len(kept) < 200
        assert polyline_distances(loop, loop[kept]).max() <= deviation + 1e-12 <= 0.001 + 1e-12

    def test_large_inputs_are_fast_without_recursion(self, rng: np.random.Generator):
        """100,000 noisy poses and a 100,000-vertex zigzag (ties everywhere) need no recursion."""
        n = 100_000
        t = np.linspace(0, 60 * np.pi, n)
        walk = np.stack([5 * np.cos(t) + 0.01 * t, 3 * np.sin(t), 1.3 + 0.1 * np.sin(5 * t)], 1)
        noisy = walk + rng.normal(0, 0.0005, walk.shape)
        zigzag = np.stack([np.arange(n) * 0.01, (np.arange(n) % 2) * 0.1, np.zeros(n)], 1)
        # How fast: benchmarks/polyline.py (a timing here fails on a loaded machine).
        kept_walk, _ = simplify_rdp(walk, 0.001)
        _, dev_noisy = simplify_rdp(noisy, 0.001)
        kept_zigzag, _ = simplify_rdp(zigzag, 0.001)
        assert len(kept_walk) < n / 10
        assert len(kept_zigzag) == n
        assert dev_noisy <= 0.001

    def test_polyline_distances_brute_force(self, rng: np.random.Generator):
        """Distances to a polyline match a per-segment computation, including a single vertex."""
        points = rng.normal(size=(50, 3))
        vertices = rng.normal(size=(7, 3))
        expected = np.full(50, np.inf)
        for a, b in itertools.pairwise(vertices):
            t = np.clip((points - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
            expected = np.minimum(
                expected, np.linalg.norm(points - (a + t[:, None] * (b - a)), axis=1)
            )
        np.testing.assert_allclose(polyline_distances(points, vertices), expected, rtol=1e-12)
        single = polyline_distances(points, vertices[:1])
        np.testing.assert_allclose(single, np.linalg.norm(points - vertices[0], axis=1))


@pytest.mark.parametrize("tolerance", [0.0, 0.005, 0.02, 0.2])
def test_runs_simplify_as_each_run_alone(rng: np.random.Generator, tolerance: float) -> None:
    """Many runs in one work list keep the vertices and deviation of one call per run."""
    points = np.cumsum(rng.normal(size=(3000, 3)) * 0.01, axis=0)
    points[1000:1200] = np.round(points[1000:1200], 2)  # ties: the split nearest the middle
    cuts = np.sort(rng.choice(np.arange(1, 3000), 500, replace=False))
    starts = np.concatenate(([0], cuts))
    stops = np.concatenate((cuts + 1, [3000]))  # each run shares its last point with the next
    long_enough = stops - starts >= 2
    starts, stops = starts[long_enough], stops[long_enough]

    keep, deviation = simplify_rdp_runs(points, starts, stops, tolerance)

    alone = [simplify_rdp(points[a:b], tolerance) for a, b in zip(starts, stops, strict=True)]
    for (a, b), (kept, _) in zip(zip(starts, stops, strict=True), alone, strict=True):
        np.testing.assert_array_equal(np.flatnonzero(keep[a:b]), kept)
    assert deviation == max(d for _, d in alone)
    assert deviation <= tolerance
