"""Tests for loceval.readers.tftree: links, coverage, interpolation and chain composition."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from loceval.core.geometry import SimilarityTransform
from loceval.errors import ReaderError
from loceval.readers.tftree import (
    DEFAULT_MIN_GAP_NS,
    TfBuffer,
    TfLink,
    compose_chain,
    compose_static_chain,
    describe_chain,
    find_chain,
)

NS = 1_000_000_000
T0 = 1_700_000_000 * NS


def random_link(rng: np.random.Generator, parent: str, child: str, stamps: np.ndarray) -> TfLink:
    n = stamps.shape[0]
    return TfLink(
        parent,
        child,
        stamps,
        rng.normal(size=(n, 3)),
        Rotation.random(n, random_state=rng).as_quat(),
    )


def static_link(rng: np.random.Generator, parent: str, child: str) -> TfLink:
    return TfLink(
        parent,
        child,
        np.array([0]),
        rng.normal(size=(1, 3)),
        Rotation.random(1, random_state=rng).as_quat(),
        is_static=True,
    )


def transform_at(link: TfLink, stamp: int) -> SimilarityTransform:
    """Reference implementation: one pose at a time with scipy's Slerp."""
    s = link.stamps_ns
    if link.is_static or len(link) == 1:
        return SimilarityTransform.from_pose(link.translations_xyz[-1], link.quat_xyzw[-1])
    i = int(np.clip(np.searchsorted(s, stamp, side="right") - 1, 0, len(s) - 2))
    w = (stamp - s[i]) / (s[i + 1] - s[i])
    p = link.translations_xyz[i] + w * (link.translations_xyz[i + 1] - link.translations_xyz[i])
    r0 = Rotation.from_quat(link.quat_xyzw[i])
    r1 = Rotation.from_quat(link.quat_xyzw[i + 1])
    r = r0 * Rotation.from_rotvec(w * (r0.inv() * r1).as_rotvec())
    return SimilarityTransform(r.as_matrix(), p)


def assert_same_rotations(q_a: np.ndarray, q_b: np.ndarray, atol: float = 1e-9) -> None:
    angle = (Rotation.from_quat(q_a).inv() * Rotation.from_quat(q_b)).magnitude()
    assert np.max(angle) < atol


@pytest.fixture
def robot(rng: np.random.Generator) -> TfBuffer:
    """map -> odom (10 Hz) -> base_link (30 Hz) -> camera (static), plus a wheel."""
    odom_stamps = T0 + np.arange(0, 10 * NS, NS // 10)
    base_stamps = T0 + NS // 60 + np.arange(0, 12 * NS, NS // 30)
    return TfBuffer(
        (
            random_link(rng, "map", "odom", odom_stamps),
            random_link(rng, "odom", "base_link", base_stamps),
            static_link(rng, "base_link", "camera"),
            random_link(rng, "base_link", "wheel", base_stamps[::2]),
        )
    )


class TestTfLink:
    def test_sorts_deduplicates_and_normalizes(self):
        """Samples are sorted by stamp, repeated stamps keep the first, quaternions are unit."""
        link = TfLink(
            "a",
            "b",
            np.array([30, 10, 20, 10]),
            np.array([[3.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0], [9.0, 0, 0]]),
            np.array([[0, 0, 0, 2.0]] * 4),
        )
        np.testing.assert_array_equal(link.stamps_ns, [10, 20, 30])
        np.testing.assert_array_equal(link.translations_xyz[:, 0], [1.0, 2.0, 3.0])
        np.testing.assert_allclose(np.linalg.norm(link.quat_xyzw, axis=1), 1.0)
        assert link.message_count == 4
        assert not link.stamps_ns.flags.writeable

    def test_rejects_bad_shapes(self):
        """Mismatched array shapes are a ReaderError naming the link."""
        with pytest.raises(ReaderError, match="'a' → 'b'"):
            TfLink("a", "b", np.array([1, 2]), np.zeros((2, 3)), np.zeros((3, 4)))

    def test_rejects_a_link_without_any_valid_sample(self):
        """A link whose every quaternion is zero cannot be used: a ReaderError naming it."""
        with pytest.raises(ReaderError, match="'a' → 'b' holds only NaN, inf or zero"):
            TfLink("a", "b", np.array([1]), np.zeros((1, 3)), np.zeros((1, 4)))

    def test_drops_and_counts_invalid_samples(self):
        """NaN translations and zero quaternions drop those samples only, and are counted."""
        translations = np.zeros((4, 3))
        translations[1, 0] = np.nan
        quats = np.tile([0, 0, 0, 1.0], (4, 1))
        quats[2] = 0.0
        link = TfLink("a", "b", np.array([1, 2, 3, 4]), translations, quats)
        np.testing.assert_array_equal(link.stamps_ns, [1, 4])
        assert link.invalid_count == 2

    def test_rate_and_default_gap(self):
        """Rate comes from the median interval; the default gap is max(0.1 s, 3 intervals)."""
        stamps = T0 + np.arange(0, NS, NS // 10)
        link = TfLink("a", "b", stamps, np.zeros((10, 3)), np.tile([0, 0, 0, 1.0], (10, 1)))
        assert link.rate_hz == pytest.approx(10.0)
        assert link.default_max_gap_ns() == 3 * (NS // 10)
        fast = TfLink(
            "a",
            "b",
            T0 + np.arange(0, NS, NS // 100),
            np.zeros((100, 3)),
            np.tile([0, 0, 0, 1.0], (100, 1)),
        )
        assert fast.default_max_gap_ns() == DEFAULT_MIN_GAP_NS

    def test_covers_without_extrapolation(self):
        """Coverage holds inside the range and across short gaps, never outside or in gaps."""
        stamps = np.array([0, 10, 20, 500, 510])
        link = TfLink("a", "b", stamps, np.zeros((5, 3)), np.tile([0, 0, 0, 1.0], (5, 1)))
        query = np.array([-1, 0, 5, 20, 100, 500, 505, 510, 511])
        expected = [False, True, True, True, False, True, True, True, False]
        np.testing.assert_array_equal(link.covers(query, max_gap_ns=50), expected)
        assert link.covers(query, max_gap_ns=1000)[4]

    def test_static_link_covers_everything(self, rng):
        """A static link holds at every time."""
        link = static_link(rng, "a", "b")
        assert link.covers(np.array([-(10**18), 0, 10**18])).all()

    def test_single_sample_dynamic_link_covers_its_stamp_only(self):
        """A dynamic link with one sample covers exactly that stamp."""
        link = TfLink("a", "b", np.array([5]), np.zeros((1, 3)), np.array([[0, 0, 0, 1.0]]))
        np.testing.assert_array_equal(link.covers(np.array([4, 5, 6])), [False, True, False])

    def test_interpolates_linearly_and_by_slerp(self):
        """Halfway between two samples: mean translation, half the rotation angle."""
        q1 = Rotation.from_euler("z", 90, degrees=True).as_quat()
        link = TfLink(
            "a",
            "b",
            np.array([T0, T0 + NS]),
            np.array([[0.0, 0, 0], [2.0, 4.0, 0]]),
            np.array([[0, 0, 0, 1.0], q1]),
        )
        t, q = link.at(np.array([T0, T0 + NS // 2, T0 + NS]))
        np.testing.assert_allclose(t, [[0, 0, 0], [1.0, 2.0, 0], [2.0, 4.0, 0]], atol=1e-12)
        np.testing.assert_allclose(
            Rotation.from_quat(q).as_euler("xyz", degrees=True)[:, 2], [0, 45, 90]
        )

    def test_samples_are_returned_exactly(self, rng):
        """Querying a link at its own stamps returns its samples unchanged."""
        link = random_link(rng, "a", "b", T0 + np.arange(50) * 7_000_000)
        t, q = link.at(link.stamps_ns)
        np.testing.assert_array_equal(t, link.translations_xyz)
        np.testing.assert_array_equal(q, link.quat_xyzw)


class TestFindChain:
    def test_up_and_down(self, robot):
        """A chain goes up to the common ancestor and down again."""
        steps = find_chain(robot, "camera", "wheel")
        assert [(s.link.name, s.inverted) for s in steps] == [
            ("base_link → camera", True),
            ("base_link → wheel", False),
        ]
        assert describe_chain(steps) == "camera ← base_link → wheel"

    def test_down_from_root(self, robot):
        """A chain from the root walks every link forwards."""
        assert describe_chain(find_chain(robot, "map", "camera")) == (
            "map → odom → base_link → camera"
        )

    def test_leading_slash_ignored(self, robot):
        """ROS 1 style frame ids with a leading slash find the same chain."""
        assert len(find_chain(robot, "/map", "/base_link")) == 2

    def test_unknown_frame_lists_frames(self, robot):
        """An unknown frame names the frames there are and what to type."""
        with pytest.raises(ReaderError, match=r"'world'.*base_link, camera, map, odom, wheel.*tf:"):
            find_chain(robot, "world", "base_link")

    def test_disconnected_trees(self, rng, robot):
        """Frames of two trees have no chain; the roots are named."""
        buffer = TfBuffer((*robot.links, static_link(rng, "world", "marker")))
        with pytest.raises(ReaderError, match=r"No tf path from 'marker' to 'camera'.*'world'"):
            find_chain(buffer, "marker", "camera")

    def test_two_parents(self, rng):
        """A frame with two parents breaks every chain through it."""
        stamps = T0 + np.arange(5) * NS
        buffer = TfBuffer(
            (random_link(rng, "map", "base", stamps), random_link(rng, "odom", "base", stamps))
        )
        with pytest.raises(ReaderError, match=r"'base' has 2 parents.*'map', 'odom'"):
            find_chain(buffer, "map", "base")

    def test_loop(self, rng):
        """Links that form a loop are reported."""
        stamps = T0 + np.arange(5) * NS
        buffer = TfBuffer((random_link(rng, "a", "b", stamps), random_link(rng, "b", "a", stamps)))
        with pytest.raises(ReaderError, match="loop"):
            find_chain(buffer, "a", "b")

    def test_repeated_pair_rejected(self, rng):
        """A buffer holds one link per parent/child pair."""
        stamps = T0 + np.arange(5) * NS
        link = random_link(rng, "a", "b", stamps)
        with pytest.raises(ReaderError, match="given twice"):
            TfBuffer((link, link))

    def test_roots(self, robot):
        """The root of every frame of the robot is map."""
        assert robot.roots() == ("map",)
        assert robot.root_of("camera") == "map"


class TestComposeChain:
    def test_matches_pose_by_pose_reference(self, robot):
        """map -> camera equals a pose-by-pose composition at the fastest link's stamps."""
        chain = compose_chain(robot, "map", "camera")
        base = robot.link("odom", "base_link")
        assert base is not None
        covered = (base.stamps_ns >= T0) & (base.stamps_ns <= T0 + 9 * NS + 9 * (NS // 10))
        np.testing.assert_array_equal(chain.stamps_ns, base.stamps_ns[covered])
        assert chain.dropped == int((~covered).sum())
        for k in range(0, len(chain.stamps_ns), 17):
            stamp = int(chain.stamps_ns[k])
            expected = SimilarityTransform.identity()
            for parent, child in (("map", "odom"), ("odom", "base_link"), ("base_link", "camera")):
                link = robot.link(parent, child)
                assert link is not None
                expected = expected.compose(transform_at(link, stamp))
            np.testing.assert_allclose(chain.positions_xyz[k], expected.translation, atol=1e-9)
            assert_same_rotations(
                chain.quat_xyzw[k : k + 1], Rotation.from_matrix(expected.rotation).as_quat()[None]
            )

    def test_inverse_chain(self, robot):
        """camera -> map is the inverse of map -> camera at the same stamps."""
        forward = compose_chain(robot, "map", "camera")
        backward = compose_chain(robot, "camera", "map")
        np.testing.assert_array_equal(forward.stamps_ns, backward.stamps_ns)
        r_fwd = Rotation.from_quat(forward.quat_xyzw)
        np.testing.assert_allclose(
            backward.positions_xyz, -(r_fwd.inv().apply(forward.positions_xyz)), atol=1e-9
        )
        assert_same_rotations(backward.quat_xyzw, r_fwd.inv().as_quat())

    def test_up_and_down_chain(self, robot):
        """camera -> wheel composes inv(base->camera) with base->wheel."""
        chain = compose_chain(robot, "camera", "wheel")
        cam, wheel = robot.link("base_link", "camera"), robot.link("base_link", "wheel")
        assert cam is not None
        assert wheel is not None
        np.testing.assert_array_equal(chain.stamps_ns, wheel.stamps_ns)
        t_cam = SimilarityTransform.from_pose(cam.translations_xyz[0], cam.quat_xyzw[0])
        for k in (0, 5, len(chain.stamps_ns) - 1):
            t_wheel = SimilarityTransform.from_pose(wheel.translations_xyz[k], wheel.quat_xyzw[k])
            expected = t_cam.inverse().compose(t_wheel)
            np.testing.assert_allclose(chain.positions_xyz[k], expected.translation, atol=1e-9)

    def test_gap_drops_poses(self, rng):
        """Poses inside a gap of a slow link are dropped unless the max gap allows it."""
        slow = T0 + np.concatenate(
            [np.arange(0, 2 * NS, NS // 10), np.arange(3 * NS, 5 * NS, NS // 10)]
        )
        fast = T0 + np.arange(0, 5 * NS, NS // 50)
        buffer = TfBuffer(
            (random_link(rng, "map", "odom", slow), random_link(rng, "odom", "base", fast))
        )
        chain = compose_chain(buffer, "map", "base")
        in_gap = (fast > T0 + 19 * (NS // 10)) & (fast < T0 + 3 * NS)
        after_end = fast > slow[-1]
        assert chain.dropped == int((in_gap | after_end).sum())
        assert not np.isin(chain.stamps_ns, fast[in_gap]).any()
        bridged = compose_chain(buffer, "map", "base", max_gap_ns=2 * NS)
        assert bridged.dropped == int(after_end.sum())

    def test_tuple_unpacking(self, robot):
        """The result unpacks as (stamps, positions, quats, dropped)."""
        stamps, positions, quats, dropped = compose_chain(robot, "odom", "base_link")
        assert positions.shape == (stamps.shape[0], 3)
        assert quats.shape == (stamps.shape[0], 4)
        assert dropped == 0

    def test_no_overlap_gives_no_poses(self, rng):
        """Links that never overlap in time give zero poses, all counted as dropped."""
        buffer = TfBuffer(
            (
                random_link(rng, "map", "odom", T0 + np.arange(10) * NS),
                random_link(rng, "odom", "base", T0 + (100 + np.arange(20)) * NS),
            )
        )
        chain = compose_chain(buffer, "map", "base")
        assert chain.stamps_ns.shape == (0,)
        assert chain.dropped == 20

    def test_static_only_chain_is_refused(self, robot):
        """A chain of static links is an offset, not a trajectory."""
        with pytest.raises(ReaderError, match="no dynamic link"):
            compose_chain(robot, "base_link", "camera")


class TestComposeStaticChain:
    def test_static_offset(self, rng):
        """Static links compose to the product of their transforms."""
        a, b = static_link(rng, "body", "mount"), static_link(rng, "mount", "camera")
        result = compose_static_chain(TfBuffer((a, b)), "body", "camera")
        expected = SimilarityTransform.from_pose(a.translations_xyz[0], a.quat_xyzw[0]).compose(
            SimilarityTransform.from_pose(b.translations_xyz[0], b.quat_xyzw[0])
        )
        np.testing.assert_allclose(result.as_matrix(), expected.as_matrix(), atol=1e-12)
        back = compose_static_chain(TfBuffer((a, b)), "camera", "body")
        np.testing.assert_allclose(back.as_matrix(), expected.inverse().as_matrix(), atol=1e-12)

    def test_dynamic_link_refused(self, robot):
        """A chain with a /tf link is no fixed offset; the link is named."""
        with pytest.raises(ReaderError, match="odom → base_link"):
            compose_static_chain(robot, "odom", "camera")
