"""Tests for loceval.readers.rosbag, on bags written here with rosbags' writers."""

from __future__ import annotations

import dataclasses
import os
import shutil
import sqlite3
import struct
import zipfile
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.rosbag2 import Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from scipy.spatial.transform import Rotation

from loceval.errors import InputError, ReaderError
from loceval.readers._mcap import read_indexed_messages
from loceval.readers.rosbag import (
    SUPPORTED_MSGTYPES,
    StampSource,
    is_bag_path,
    read_bag_static_transform,
    read_bag_tf_buffer,
    read_bag_trajectory,
)
from loceval.readers.rosbag import tf as rosbag_tf
from loceval.readers.rosbag.bagfile import converted
from loceval.readers.tftree import TfBuffer, TfLink, compose_chain
from tests import bagfactory as bf

NS = bf.NS
T0 = bf.T0_NS


def assert_poses(traj, poses: bf.Poses, *, orientation: bool = True, atol: float = 1e-12) -> None:
    np.testing.assert_array_equal(traj.stamps_ns, poses.stamps_ns)
    np.testing.assert_allclose(traj.positions_xyz, poses.positions, atol=atol)
    if orientation:
        assert traj.quat_xyzw is not None
        dots = np.abs(np.sum(traj.quat_xyzw * poses.quats, axis=1))
        np.testing.assert_allclose(dots, 1.0, atol=1e-9)
    else:
        assert traj.quat_xyzw is None


def write(tmp_path: Path, records, *, fmt: str, name: str = "rec", **kwargs) -> Path:
    return bf.write_bag(bf.bag_path(tmp_path, fmt, name), records, fmt=fmt, **kwargs)


def images(n: int = 20, *, dt_ns: int = 100_000_000) -> list[bf.Record]:
    return [bf.image_record("/camera/image", T0 + i * dt_ns) for i in range(n)]


@pytest.fixture
def poses(rng: np.random.Generator) -> bf.Poses:
    return bf.random_poses(rng, 60, dt_ns=20_000_000)


@pytest.fixture
def tf_setup(rng: np.random.Generator) -> tuple[list[bf.Record], TfBuffer]:
    """map -> odom at 10 Hz, odom -> base_link at 30 Hz, static base_link -> camera."""
    odom = bf.random_poses(rng, 40, dt_ns=100_000_000)
    base = bf.random_poses(rng, 150, start_ns=T0 - 200_000_000, dt_ns=33_333_333)
    camera_xyz = np.array([0.2, 0.0, 0.3])
    camera_quat = Rotation.from_euler("xyz", [-90, 0, -90], degrees=True).as_quat()
    records = [
        *bf.tf_records(bf.link_transforms("map", "odom", odom)),
        *bf.tf_records(bf.link_transforms("odom", "base_link", base)),
        *bf.tf_records(
            [bf.Tf(T0 - 10 * NS, "base_link", "camera", camera_xyz, camera_quat)],
            topic="/tf_static",
            receive_delay_ns=10 * NS - 300_000_000,
        ),
        *images(),
    ]
    buffer = TfBuffer(
        (
            TfLink("map", "odom", odom.stamps_ns, odom.positions, odom.quats),
            TfLink("odom", "base_link", base.stamps_ns, base.positions, base.quats),
            TfLink(
                "base_link",
                "camera",
                np.array([T0 - 10 * NS]),
                camera_xyz[None],
                camera_quat[None],
                is_static=True,
            ),
        )
    )
    return records, buffer


class TestPoseTopics:
    @pytest.mark.parametrize("fmt", bf.FORMATS)
    @pytest.mark.parametrize("msgtype", [bf.POSE, bf.POSE_COV, bf.TRANSFORM, bf.ODOMETRY])
    def test_pose_types(self, tmp_path, poses, fmt, msgtype):
        """Every stamped pose type reads back exactly, in every container."""
        records = bf.pose_records("/pose", msgtype, poses) + images()
        bag = write(tmp_path, records, fmt=fmt)
        traj = read_bag_trajectory(bag, "/pose")
        assert_poses(traj, poses)
        assert traj.name == "/pose"
        assert traj.source == f"{bag.name}@/pose"
        assert traj.frame_id == "map"
        has_child = msgtype in {bf.TRANSFORM, bf.ODOMETRY}
        assert traj.child_frame_id == ("base_link" if has_child else "")

    @pytest.mark.parametrize("fmt", bf.FORMATS)
    @pytest.mark.parametrize("msgtype", [bf.POSE_COV, bf.ODOMETRY])
    def test_covariance_follows_the_sorted_poses(self, tmp_path, rng, fmt, msgtype):
        """The 6x6 covariances are read row-major and sorted and deduplicated with the poses."""
        poses = bf.random_poses(rng, 12, dt_ns=20_000_000)
        order = np.array([0, 2, 1, 3, 4, 5, 6, 7, 8, 9, 10, 11, 11])  # one swap, one repeat
        base = rng.normal(size=(12, 6, 6))
        covs = base @ base.transpose(0, 2, 1)  # symmetric positive definite, all distinct
        records = [
            bf.Record(
                "/pose",
                msgtype,
                T0 + k * 20_000_000,
                (int(poses.stamps_ns[i]), poses.positions[i], poses.quats[i]),
                extra={"covariance": covs[i] + (k == 12)},  # the repeat differs: dropped
            )
            for k, i in enumerate(order)
        ]
        traj = read_bag_trajectory(write(tmp_path, records, fmt=fmt), "/pose")
        assert_poses(traj, poses)
        assert traj.cov6 is not None
        np.testing.assert_allclose(traj.cov6, covs, rtol=0, atol=0)
        assert any("sorted by time" in w for w in traj.warnings)
        assert any("duplicate stamp" in w for w in traj.warnings)

    @pytest.mark.parametrize(
        ("first", "note"),
        [(0.0, None), (-1.0, None), (float("nan"), "not finite and symmetric")],
    )
    def test_unreported_covariance_is_none(self, tmp_path, poses, first, note):
        """All-zero, -1 ("unknown") or broken covariances leave cov6 None."""
        cov = np.zeros((6, 6))
        cov[0, 0] = first
        records = [
            dataclasses.replace(r, extra={"covariance": cov})
            for r in bf.pose_records("/pose", bf.POSE_COV, poses)
        ]
        traj = read_bag_trajectory(write(tmp_path, records, fmt="mcap"), "/pose")
        assert traj.cov6 is None
        assert any(note in w for w in traj.warnings) if note else not traj.warnings

    @pytest.mark.public_data
    def test_nav2_amcl_covariance(self, public_data):
        """AMCL's /amcl_pose carries its planar covariance; /odom reports none (all zero)."""
        bag = public_data / "nav2_turtlebot.mcap"
        amcl = read_bag_trajectory(bag, "/amcl_pose")
        assert amcl.cov6 is not None
        assert amcl.cov6.shape == (135, 6, 6)
        assert (amcl.cov6[:, 2, 2] == 0).all()  # z not estimated by a planar filter
        assert (amcl.cov6[:, 0, 0] > 0).all()
        assert (amcl.cov6[:, 5, 5] > 0).all()  # yaw
        # The first message read directly with rosbags, without loceval's reader.
        with AnyReader([bag]) as reader:
            conn = next(c for c in reader.connections if c.topic == "/amcl_pose")
            first = next(reader.messages([conn]))
            msg = reader.deserialize(first[2], conn.msgtype)
        np.testing.assert_array_equal(amcl.cov6[0].ravel(), msg.pose.covariance)
        assert read_bag_trajectory(bag, "/odom").cov6 is None

    @pytest.mark.parametrize("fmt", bf.FORMATS)
    def test_point_stamped_has_no_orientation(self, tmp_path, poses, fmt):
        """PointStamped gives positions only."""
        bag = write(tmp_path, bf.pose_records("/uwb", bf.POINT, poses), fmt=fmt)
        traj = read_bag_trajectory(bag, "/uwb", name="UWB")
        assert_poses(traj, poses, orientation=False)
        assert traj.name == "UWB"

    @pytest.mark.parametrize("fmt", bf.FORMATS)
    def test_path_uses_last_message(self, tmp_path, poses, fmt):
        """A nav_msgs/Path topic yields the poses of its last message, stamped per pose."""
        bag = write(tmp_path, bf.path_records("/plan", poses, cuts=[10, 35, 60]), fmt=fmt)
        traj = read_bag_trajectory(bag, "/plan")
        assert_poses(traj, poses)
        assert any("last message" in w for w in traj.warnings)

    @pytest.mark.parametrize("fmt", bf.FORMATS)
    def test_receive_stamps(self, tmp_path, poses, fmt):
        """StampSource.RECEIVE stamps poses with the bag's receive times."""
        bag = write(tmp_path, bf.pose_records("/pose", bf.POSE, poses, receive_delay_ns=7), fmt=fmt)
        traj = read_bag_trajectory(bag, "/pose", stamp=StampSource.RECEIVE)
        np.testing.assert_array_equal(traj.stamps_ns, poses.stamps_ns + 7)
        assert read_bag_trajectory(bag, "/pose", stamp="receive").stamps_ns[0] == traj.stamps_ns[0]

    def test_ros1_topic_without_slash(self, tmp_path, poses):
        """A ROS 1 topic recorded without a leading slash is found with or without it."""
        bag = write(tmp_path, bf.pose_records("groundtruth", bf.POSE, poses), fmt="rosbag1")
        assert len(read_bag_trajectory(bag, "groundtruth")) == 60
        traj = read_bag_trajectory(bag, "/groundtruth")
        assert traj.source == "rec.bag@/groundtruth"

    def test_ros2_topic_without_slash(self, tmp_path, poses):
        """A ROS 2 topic can be typed without its leading slash."""
        bag = write(tmp_path, bf.pose_records("/pose", bf.POSE, poses), fmt="mcap")
        assert len(read_bag_trajectory(bag, "pose")) == 60

    def test_exact_topic_wins(self, tmp_path, poses, rng):
        """When 'x' and '/x' both exist, the exact name is read."""
        other = bf.random_poses(rng, 30, dt_ns=20_000_000)
        records = bf.pose_records("pose", bf.POSE, poses) + bf.pose_records("/pose", bf.POSE, other)
        bag = write(tmp_path, records, fmt="rosbag1")
        assert len(read_bag_trajectory(bag, "pose")) == 60
        assert len(read_bag_trajectory(bag, "/pose")) == 30

    @pytest.mark.parametrize("fmt", bf.FORMATS)
    def test_unsorted_and_duplicate_stamps(self, tmp_path, poses, fmt):
        """Header stamps out of order are sorted and duplicates dropped, with warnings."""
        records = bf.pose_records("/pose", bf.POSE, poses)
        first, second = records[0], records[1]
        records[0] = dataclasses.replace(first, payload=second.payload)
        records[1] = dataclasses.replace(second, payload=first.payload)
        duplicate = records[5]
        records.append(dataclasses.replace(duplicate, receive_ns=duplicate.receive_ns + 1))
        bag = write(tmp_path, records, fmt=fmt)
        traj = read_bag_trajectory(bag, "/pose")
        assert len(traj) == 60
        assert any("not in order" in w for w in traj.warnings)
        assert any("duplicate" in w for w in traj.warnings)


class TestCompression:
    @pytest.mark.parametrize(
        ("fmt", "compression"),
        [
            ("rosbag1", "bz2"),
            ("rosbag1", "lz4"),
            ("sqlite3", "message"),
            ("sqlite3", "file"),
            ("mcap", "message"),
            ("mcap", "file"),
            ("mcap", "storage"),
        ],
    )
    def test_compressed_bags_read_like_plain_ones(
        self, tmp_path, poses, tf_setup, fmt, compression
    ):
        """Compressed chunks, messages and files give the same poses and tf chains."""
        tf_records, buffer = tf_setup
        records = bf.pose_records("/pose", bf.POSE, poses) + tf_records
        bag = write(tmp_path, records, fmt=fmt, compression=compression)
        assert_poses(read_bag_trajectory(bag, "/pose"), poses)
        chain = read_bag_trajectory(bag, "tf:map:camera")
        expected = compose_chain(buffer, "map", "camera")
        np.testing.assert_allclose(chain.positions_xyz, expected.positions_xyz, atol=1e-12)


class TestTf:
    @pytest.mark.parametrize("fmt", bf.FORMATS)
    def test_chain_with_static_link(self, tmp_path, tf_setup, fmt):
        """tf:map:camera composes map->odom (10 Hz), odom->base_link (30 Hz) and a static link."""
        records, buffer = tf_setup
        bag = write(tmp_path, records, fmt=fmt)
        traj = read_bag_trajectory(bag, "tf:map:camera")
        expected = compose_chain(buffer, "map", "camera")
        assert expected.dropped > 0
        np.testing.assert_array_equal(traj.stamps_ns, expected.stamps_ns)
        np.testing.assert_allclose(traj.positions_xyz, expected.positions_xyz, atol=1e-12)
        assert traj.quat_xyzw is not None
        np.testing.assert_allclose(
            np.abs(np.sum(traj.quat_xyzw * expected.quat_xyzw, axis=1)), 1.0, atol=1e-12
        )
        assert (traj.frame_id, traj.child_frame_id) == ("map", "camera")
        assert traj.source == f"{bag.name}@tf:map:camera"
        # The chain is information (issue 30, item 12): a note, not a warning.
        assert any("map → odom → base_link → camera" in n for n in traj.notes)
        assert any(f"{expected.dropped} of" in w for w in traj.warnings)

    def test_containers_agree(self, tmp_path, tf_setup):
        """The same tf data in ROS 1, sqlite3 and MCAP gives the same chain to 1e-9."""
        records, _ = tf_setup
        trajs = [
            read_bag_trajectory(write(tmp_path, records, fmt=fmt, name=fmt), "tf:odom:camera")
            for fmt in bf.FORMATS
        ]
        for other in trajs[1:]:
            np.testing.assert_array_equal(other.stamps_ns, trajs[0].stamps_ns)
            np.testing.assert_allclose(other.positions_xyz, trajs[0].positions_xyz, atol=1e-9)

    def test_frames_with_leading_slash(self, tmp_path, rng):
        """ROS 1 tf frame ids with a leading slash are matched without it."""
        base = bf.random_poses(rng, 30, dt_ns=50_000_000)
        records = bf.tf_records(bf.link_transforms("/odom", "/base_link", base))
        bag = write(tmp_path, records, fmt="rosbag1")
        traj = read_bag_trajectory(bag, "tf:odom:base_link")
        assert_poses(traj, base)
        assert len(read_bag_trajectory(bag, "tf:/odom:/base_link")) == 30

    def test_receive_stamps(self, tmp_path, rng):
        """tf chains can be stamped with receive times."""
        base = bf.random_poses(rng, 30, dt_ns=50_000_000)
        records = bf.tf_records(bf.link_transforms("odom", "base_link", base), receive_delay_ns=3)
        bag = write(tmp_path, records, fmt="mcap")
        traj = read_bag_trajectory(bag, "tf:odom:base_link", stamp=StampSource.RECEIVE)
        np.testing.assert_array_equal(traj.stamps_ns, base.stamps_ns + 3)

    def test_bulk_cdr_parser_matches_deserialization(self, tmp_path, rng, monkeypatch):
        """Bulk-decoded CDR tf messages equal rosbags' deserialization, for mixed layouts."""
        a = bf.random_poses(rng, 50, dt_ns=20_000_000)
        b = bf.random_poses(rng, 50, dt_ns=20_000_000)
        transforms = [
            *bf.link_transforms("odom", "base_link", a),
            *bf.link_transforms("odom", "base_lin2", b),  # same length, other bytes
            *bf.link_transforms("map", "odom", bf.random_poses(rng, 7, dt_ns=NS // 3)),
        ]
        records = bf.tf_records(transforms)
        records.append(
            bf.Record("/tf", bf.TF, T0 + 5 * NS, transforms[:3])  # three transforms at once
        )
        bag = write(tmp_path, records, fmt="sqlite3")
        fast = read_bag_tf_buffer(bag)
        monkeypatch.setattr(rosbag_tf, "_standard_tf_layout", lambda _: False)
        slow = read_bag_tf_buffer(bag)
        assert [x.name for x in fast.links] == [x.name for x in slow.links]
        for x, y in zip(fast.links, slow.links, strict=True):
            np.testing.assert_array_equal(x.stamps_ns, y.stamps_ns)
            np.testing.assert_array_equal(x.translations_xyz, y.translations_xyz)
            np.testing.assert_array_equal(x.quat_xyzw, y.quat_xyzw)
            assert x.message_count == y.message_count

    def test_big_endian_cdr(self, tmp_path, rng):
        """Big-endian CDR tf messages are deserialized generically and read the same."""
        base = bf.random_poses(rng, 30, dt_ns=50_000_000)
        records = bf.tf_records(bf.link_transforms("odom", "base_link", base))
        bag = write(tmp_path, records, fmt="sqlite3", little_endian=False)
        assert_poses(read_bag_trajectory(bag, "tf:odom:base_link"), base)

    def test_tf_rihs01_is_the_standard_hash(self):
        """The CDR parser's type hash is the standard tf2_msgs/msg/TFMessage hash."""
        store = get_typestore(Stores.ROS2_HUMBLE)
        assert store.hash_rihs01("tf2_msgs/msg/TFMessage") == rosbag_tf._TF_RIHS01

    def test_static_transform(self, tmp_path, tf_setup):
        """read_bag_static_transform returns the /tf_static offset and its inverse."""
        records, buffer = tf_setup
        bag = write(tmp_path, records, fmt="mcap")
        offset = read_bag_static_transform(bag, "base_link", "camera")
        link = buffer.link("base_link", "camera")
        assert link is not None
        np.testing.assert_allclose(offset.translation, link.translations_xyz[0], atol=1e-15)
        back = read_bag_static_transform(bag, "camera", "base_link")
        np.testing.assert_allclose(back.as_matrix() @ offset.as_matrix(), np.eye(4), atol=1e-12)

    def test_static_transform_refuses_dynamic_links(self, tmp_path, tf_setup):
        """A static offset through a /tf link is refused."""
        records, _ = tf_setup
        bag = write(tmp_path, records, fmt="mcap")
        with pytest.raises(ReaderError, match="odom → base_link"):
            read_bag_static_transform(bag, "odom", "camera")

    def test_static_transform_without_tf(self, tmp_path, poses):
        """A bag without tf data has no static transform."""
        bag = write(tmp_path, bf.pose_records("/pose", bf.POSE, poses), fmt="mcap")
        with pytest.raises(ReaderError, match="holds no tf data"):
            read_bag_static_transform(bag, "a", "b")

    def test_latest_static_message_wins(self, tmp_path, rng):
        """A re-published static link takes its last message, whatever the stamps."""
        base = bf.random_poses(rng, 10, dt_ns=50_000_000)
        records = [
            *bf.tf_records(bf.link_transforms("odom", "base_link", base)),
            *bf.tf_records(
                [bf.Tf(T0 + NS, "base_link", "cam", (1, 0, 0), (0, 0, 0, 1))],
                topic="/tf_static",
                receive_delay_ns=0,
            ),
            *bf.tf_records(
                [bf.Tf(T0, "base_link", "cam", (2, 0, 0), (0, 0, 0, 1))],
                topic="/tf_static",
                receive_delay_ns=2 * NS,
            ),
        ]
        for fmt in bf.FORMATS:
            bag = write(tmp_path, records, fmt=fmt, name=f"s_{fmt}")
            offset = read_bag_static_transform(bag, "base_link", "cam")
            np.testing.assert_allclose(offset.translation, [2, 0, 0])


class TestMcapIndex:
    def test_index_reads_what_rosbags_reads(self, tmp_path, poses, tf_setup):
        """Messages read through the MCAP index equal rosbags' messages, in order."""
        tf_records, _ = tf_setup
        records = bf.pose_records("/pose", bf.POSE, poses) + tf_records
        bag = write(tmp_path, records, fmt="mcap")
        mcap = next(bag.glob("*.mcap"))
        wanted = [("/tf", bf.TF), ("/pose", bf.POSE), ("/tf_static", bf.TF)]
        indexed = read_indexed_messages(mcap, wanted)
        assert indexed is not None
        with AnyReader([mcap]) as reader:
            conns = [c for c in reader.connections if c.topic != "/camera/image"]
            expected = [(t, c.topic, bytes(raw)) for c, t, raw in reader.messages(conns)]
        got = [(t, wanted[i][0], bytes(data)) for t, i, data in indexed]
        assert sorted(got) == sorted(expected)
        assert [g[0] for g in got] == sorted(g[0] for g in got)

    def test_large_messages_are_read_whole(self, tmp_path, rng):
        """A message longer than the first read is completed with a second read."""
        many = [
            bf.Tf(T0, "base_link", f"sensor_{i:03d}", rng.normal(size=3), (0, 0, 0, 1))
            for i in range(40)
        ]
        bag = write(tmp_path, [bf.Record("/tf_static", bf.TF, T0, many)], fmt="mcap")
        indexed = read_indexed_messages(next(bag.glob("*.mcap")), [("/tf_static", bf.TF)])
        assert indexed is not None
        assert len(indexed[0][2]) > 512
        assert len(read_bag_tf_buffer(bag).links) == 40

    def test_compressed_chunks_fall_back(self, tmp_path, poses):
        """Zstd-compressed chunks are not served from the index (rosbags reads them)."""
        bag = write(
            tmp_path, bf.pose_records("/pose", bf.POSE, poses), fmt="mcap", compression="storage"
        )
        assert read_indexed_messages(next(bag.glob("*.mcap")), [("/pose", bf.POSE)]) is None

    def test_not_mcap(self, tmp_path):
        """Files that are not indexed MCAP give None."""
        junk = tmp_path / "junk.mcap"
        junk.write_bytes(b"\x89MCAP0\r\n" + bytes(100))
        assert read_indexed_messages(junk, [("/tf", bf.TF)]) is None
        assert read_indexed_messages(tmp_path / "missing.mcap", [("/tf", bf.TF)]) is None


class TestContainers:
    def test_split_ros1_bags(self, tmp_path, poses):
        """The files of a split ROS 1 recording read as one trajectory."""
        records = bf.pose_records("/pose", bf.POSE, poses)
        first = write(tmp_path, records[:25], fmt="rosbag1", name="run_0")
        second = write(tmp_path, records[25:], fmt="rosbag1", name="run_1")
        traj = read_bag_trajectory([first, second], "/pose")
        assert_poses(traj, poses)
        assert traj.source == "run_0.bag,run_1.bag@/pose"

    def test_split_set_must_be_ros1(self, tmp_path, poses):
        """Several paths are only accepted for ROS 1 bags."""
        records = bf.pose_records("/pose", bf.POSE, poses)
        first = write(tmp_path, records, fmt="rosbag1")
        second = write(tmp_path, records, fmt="mcap")
        with pytest.raises(ReaderError, match="split set"):
            read_bag_trajectory([first, second], "/pose")

    @pytest.mark.parametrize("fmt", bf.FORMATS)
    def test_zipped_bag(self, tmp_path, poses, fmt):
        """A zipped bag reads like the bag itself."""
        bag = write(tmp_path, bf.pose_records("/pose", bf.POSE, poses), fmt=fmt)
        archive = tmp_path / "upload.zip"
        if bag.is_dir():
            bf.zip_directory(bag, archive)
        else:
            bf.zip_file(bag, archive)
        traj = read_bag_trajectory(archive, "/pose")
        assert_poses(traj, poses)
        assert traj.source == "upload.zip@/pose"

    def test_db3_and_metadata_paths_open_the_folder(self, tmp_path, poses):
        """A .db3 or metadata.yaml inside a bag folder opens the whole bag."""
        bag = write(tmp_path, bf.pose_records("/pose", bf.POSE, poses), fmt="sqlite3")
        assert len(read_bag_trajectory(next(bag.glob("*.db3")), "/pose")) == 60
        assert len(read_bag_trajectory(bag / "metadata.yaml", "/pose")) == 60

    def test_is_bag_path(self, tmp_path, poses):
        """is_bag_path recognizes bag files, bag folders and zips."""
        bag_dir = write(tmp_path, bf.pose_records("/pose", bf.POSE, poses), fmt="sqlite3")
        assert is_bag_path(bag_dir)
        assert is_bag_path(next(bag_dir.glob("*.db3")))
        assert is_bag_path(bag_dir / "metadata.yaml")
        assert is_bag_path(tmp_path / "missing.bag")
        assert is_bag_path(tmp_path / "run.MCAP")
        assert is_bag_path(bf.zip_directory(bag_dir, tmp_path / "up.zip"))
        (tmp_path / "fake.zip").write_text("no zip")
        assert not is_bag_path(tmp_path / "fake.zip")
        (tmp_path / "plain").mkdir()
        assert not is_bag_path(tmp_path / "plain")
        assert not is_bag_path(tmp_path / "traj.tum")

    def test_supported_types_are_normalized_names(self):
        """SUPPORTED_MSGTYPES uses ROS 2 style names for all types."""
        assert all("/msg/" in name for name in SUPPORTED_MSGTYPES)
        assert "nav_msgs/msg/Path" in SUPPORTED_MSGTYPES


class TestTypes:
    def test_bag_without_message_definitions(self, tmp_path, poses, tf_setup):
        """An old ROS 2 bag without embedded definitions is read with ROS 2 Humble's types."""
        tf_records, buffer = tf_setup
        bag = write(tmp_path, bf.pose_records("/pose", bf.POSE, poses) + tf_records, fmt="sqlite3")
        with sqlite3.connect(next(bag.glob("*.db3"))) as db:
            db.execute("DELETE FROM message_definitions")
        with pytest.raises(AnyReaderError, match="no type definitions"), AnyReader([bag]):
            pass
        assert_poses(read_bag_trajectory(bag, "/pose"), poses)
        chain = read_bag_trajectory(bag, "tf:map:camera")
        expected = compose_chain(buffer, "map", "camera")
        np.testing.assert_allclose(chain.positions_xyz, expected.positions_xyz, atol=1e-12)

    def test_custom_types_elsewhere_in_the_bag(self, tmp_path, poses):
        """A custom message type on another topic, defined only in the bag, does not interfere."""
        store = get_typestore(Stores.ROS2_HUMBLE)
        store.register(get_types_from_msg("float64 value\nstring label", "my_msgs/msg/Reading"))
        reading = store.types["my_msgs/msg/Reading"]
        bag = tmp_path / "custom"
        with Writer(bag, version=9) as writer:
            custom = writer.add_connection("/reading", "my_msgs/msg/Reading", typestore=store)
            pose_conn = writer.add_connection("/pose", bf.POSE, typestore=store)
            for record in bf.pose_records("/pose", bf.POSE, poses):
                data = store.serialize_cdr(bf.build_message("sqlite3", record), bf.POSE)
                writer.write(pose_conn, record.receive_ns, data)
                value = store.serialize_cdr(reading(value=1.0, label="x"), "my_msgs/msg/Reading")
                writer.write(custom, record.receive_ns, value)
        assert_poses(read_bag_trajectory(bag, "/pose"), poses)
        with pytest.raises(ReaderError, match=r"'my_msgs/msg/Reading', which holds no pose"):
            read_bag_trajectory(bag, "/reading")

    def test_unknown_stamp_source(self, tmp_path, poses):
        """An unknown stamp source is an InputError."""
        bag = write(tmp_path, bf.pose_records("/pose", bf.POSE, poses), fmt="mcap")
        with pytest.raises(InputError, match="'arrival'"):
            read_bag_trajectory(bag, "/pose", stamp="arrival")  # type: ignore[arg-type]


class TestErrors:
    def test_missing_file(self, tmp_path):
        """A missing bag names the path."""
        with pytest.raises(ReaderError, match=r"'.*nope\.bag' does not exist"):
            read_bag_trajectory(tmp_path / "nope.bag", "/pose")

    def test_empty_path_list(self):
        """An empty list of paths is refused."""
        with pytest.raises(ReaderError, match="No bag path"):
            read_bag_trajectory([], "/pose")

    @pytest.mark.parametrize("fmt", bf.FORMATS)
    def test_truncated_bag(self, tmp_path, poses, fmt):
        """A bag cut short is a ReaderError that says so."""
        bag = write(tmp_path, bf.pose_records("/pose", bf.POSE, poses) + images(), fmt=fmt)
        file = bag if bag.is_file() else next(p for p in bag.iterdir() if p.suffix != ".yaml")
        data = file.read_bytes()
        file.write_bytes(data[: len(data) * 2 // 3])
        with pytest.raises(ReaderError, match=r"cannot be read|damaged"):
            read_bag_trajectory(bag, "/pose")

    def test_corrupted_mcap_chunks(self, tmp_path, poses):
        """Garbled chunk bytes are reported, not silently skipped."""
        records = bf.pose_records("/pose", bf.POSE, poses) + images(40)
        bag = write(tmp_path, records, fmt="mcap", compression="storage")
        file = next(bag.glob("*.mcap"))
        data = bytearray(file.read_bytes())
        for i in range(len(data) // 10, len(data) // 2):
            data[i] = (data[i] * 7 + 13) % 256
        file.write_bytes(bytes(data))
        with pytest.raises(ReaderError, match=r"cannot be read|damaged"):
            read_bag_trajectory(bag, "/pose")

    def test_unknown_topic_lists_topics(self, tmp_path, poses):
        """An unknown topic names the topics in the bag with their types."""
        bag = write(tmp_path, bf.pose_records("/pose", bf.POSE, poses) + images(), fmt="mcap")
        with pytest.raises(
            ReaderError,
            match=r"'/odom'.*/camera/image \(sensor_msgs/msg/Image\), "
            r"/pose \(geometry_msgs/msg/PoseStamped\).*tf:PARENT:CHILD",
        ):
            read_bag_trajectory(bag, "/odom")

    def test_zero_header_stamps_name_the_stamp_option(self, tmp_path, poses):
        """Unfilled header stamps: the error names the stamp option by key, no CLI flag."""
        zero = bf.Poses(np.zeros_like(poses.stamps_ns), poses.positions, poses.quats)
        records = bf.pose_records("/pose", bf.POSE, zero)
        bag = write(tmp_path, records, fmt="mcap")
        with pytest.raises(ReaderError, match=r"60 messages but only 1 distinct.*receive") as err:
            read_bag_trajectory(bag, "/pose")
        assert err.value.option == "stamp"
        assert "--" not in str(err.value)

    def test_unsupported_type_lists_supported(self, tmp_path, poses):
        """A topic of a type without a pose names the supported types."""
        bag = write(tmp_path, bf.pose_records("/pose", bf.POSE, poses) + images(), fmt="sqlite3")
        with pytest.raises(
            ReaderError, match=r"'sensor_msgs/msg/Image'.*nav_msgs/msg/Odometry.*nav_msgs/msg/Path"
        ):
            read_bag_trajectory(bag, "/camera/image")

    def test_tf_topic_as_topic(self, tmp_path, tf_setup):
        """Selecting /tf as a topic explains the tf:PARENT:CHILD form and lists frames."""
        records, _ = tf_setup
        bag = write(tmp_path, records, fmt="mcap")
        with pytest.raises(ReaderError, match=r"tf:PARENT:CHILD \(frames: base_link, camera"):
            read_bag_trajectory(bag, "/tf")

    def test_unknown_frame_lists_frames(self, tmp_path, tf_setup):
        """An unknown tf frame names the frames in the bag."""
        records, _ = tf_setup
        bag = write(tmp_path, records, fmt="rosbag1")
        with pytest.raises(ReaderError, match=r"'world'.*base_link, camera, map, odom"):
            read_bag_trajectory(bag, "tf:world:base_link")

    def test_broken_chain(self, tmp_path, tf_setup, rng):
        """Frames in two unconnected trees are reported with their roots."""
        records, _ = tf_setup
        marker = bf.random_poses(rng, 10, dt_ns=NS // 10)
        records = records + bf.tf_records(bf.link_transforms("mocap", "rigid_body", marker))
        bag = write(tmp_path, records, fmt="mcap")
        with pytest.raises(ReaderError, match=r"No tf path from 'map' to 'rigid_body'"):
            read_bag_trajectory(bag, "tf:map:rigid_body")

    @pytest.mark.parametrize("selector", ["tf:map", "tf::base_link", "tf:a:b:c"])
    def test_malformed_tf_selector(self, tmp_path, tf_setup, selector):
        """A malformed tf selector shows the expected form."""
        records, _ = tf_setup
        bag = write(tmp_path, records, fmt="mcap")
        with pytest.raises(ReaderError, match="tf:PARENT:CHILD"):
            read_bag_trajectory(bag, selector)

    def test_no_tf_in_bag(self, tmp_path, poses):
        """A tf selector on a bag without tf names the topics instead."""
        bag = write(tmp_path, bf.pose_records("/pose", bf.POSE, poses), fmt="mcap")
        with pytest.raises(ReaderError, match=r"no tf messages \(topics: /pose\)"):
            read_bag_trajectory(bag, "tf:map:base_link")

    def test_links_without_overlap(self, tmp_path, rng):
        """A chain whose links never overlap in time names their time ranges."""
        early = bf.random_poses(rng, 10, dt_ns=NS // 10)
        late = bf.random_poses(rng, 10, start_ns=T0 + 100 * NS, dt_ns=NS // 10)
        records = bf.tf_records(bf.link_transforms("map", "odom", early)) + bf.tf_records(
            bf.link_transforms("odom", "base_link", late)
        )
        bag = write(tmp_path, records, fmt="mcap")
        with pytest.raises(ReaderError, match=r"only 0 of 10 poses.*time ranges: map → odom"):
            read_bag_trajectory(bag, "tf:map:base_link")

    def test_path_with_receive_stamps(self, tmp_path, poses):
        """A Path has no per-pose receive times."""
        bag = write(tmp_path, bf.path_records("/plan", poses, cuts=[60]), fmt="mcap")
        with pytest.raises(ReaderError, match="header stamps"):
            read_bag_trajectory(bag, "/plan", stamp=StampSource.RECEIVE)

    def test_too_few_poses(self, tmp_path, poses):
        """Two poses are too few for a trajectory."""
        bag = write(tmp_path, bf.pose_records("/pose", bf.POSE, poses)[:2], fmt="mcap")
        with pytest.raises(ReaderError, match="at least 3"):
            read_bag_trajectory(bag, "/pose")

    def test_folder_without_metadata(self, tmp_path):
        """A folder that is no ROS 2 bag lists what it holds."""
        folder = tmp_path / "notabag"
        folder.mkdir()
        (folder / "readme.txt").write_text("hi")
        with pytest.raises(ReaderError, match=r"no metadata.yaml.*readme.txt"):
            read_bag_trajectory(folder, "/pose")

    def test_not_a_bag(self, tmp_path):
        """A file of another type is refused with the accepted forms."""
        path = tmp_path / "traj.tum"
        path.write_text("1 2 3 4 5 6 7 8\n")
        with pytest.raises(ReaderError, match=r"not a bag; pass a .bag, .mcap or .db3"):
            read_bag_trajectory(path, "/pose")

    def test_garbage_with_bag_suffix(self, tmp_path, rng):
        """Random bytes named .bag are a ReaderError, not a UnicodeDecodeError."""
        path = tmp_path / "junk.bag"
        path.write_bytes(rng.integers(0, 256, size=5000, dtype=np.uint8).tobytes())
        with pytest.raises(ReaderError, match="cannot be read"):
            read_bag_trajectory(path, "/pose")

    def test_incomplete_bag_folder(self, tmp_path, poses):
        """A bag folder missing its database file is reported."""
        bag = write(tmp_path, bf.pose_records("/pose", bf.POSE, poses), fmt="sqlite3")
        next(bag.glob("*.db3")).unlink()
        with pytest.raises(ReaderError, match="cannot be read"):
            read_bag_trajectory(bag, "/pose")

    def test_zip_without_bag(self, tmp_path):
        """A zip without a bag lists its contents."""
        archive = tmp_path / "upload.zip"
        folder = tmp_path / "docs"
        folder.mkdir()
        (folder / "notes.txt").write_text("hi")
        bf.zip_directory(folder, archive)
        with pytest.raises(ReaderError, match=r"holds no bag.*docs/notes.txt"):
            read_bag_trajectory(archive, "/pose")

    def test_zip_traversal(self, tmp_path):
        """A zip with a member escaping the extraction folder is refused."""
        archive = tmp_path / "evil.zip"
        with zipfile.ZipFile(archive, "w") as z:
            z.writestr("rec/metadata.yaml", "x")
            z.writestr("../../outside.txt", "boom")
        with pytest.raises(ReaderError, match="leaves the extraction folder"):
            read_bag_trajectory(archive, "/pose")

    def test_zip_bomb(self, tmp_path):
        """A zip bomb is refused before it is inflated."""
        archive = tmp_path / "bomb.zip"
        with zipfile.ZipFile(archive, "w", compression=zipfile.ZIP_DEFLATED) as z:
            z.writestr("rec/metadata.yaml", "x")
            z.writestr("rec/rec_0.db3", bytes(16 * 1024**2))
        with pytest.raises(ReaderError, match="zip bomb"):
            read_bag_trajectory(archive, "/pose")


@pytest.mark.public_data
class TestPublicData:
    @pytest.mark.parametrize(
        ("selector", "count"), [("groundtruth", 12765), ("ORB-SLAM", 8362), ("S-PTAM", 5439)]
    )
    def test_ros_example(self, public_data, selector, count):
        """ROS_example.bag's PoseStamped topics have their known pose counts."""
        traj = read_bag_trajectory(public_data / "ROS_example.bag", selector)
        assert len(traj) == count
        assert traj.source == f"ROS_example.bag@{selector}"

    def test_nav2_amcl_and_odom(self, public_data):
        """nav2_turtlebot.mcap gives 135 AMCL poses and 2639 odometry poses."""
        bag = public_data / "nav2_turtlebot.mcap"
        amcl = read_bag_trajectory(bag, "/amcl_pose")
        assert len(amcl) == 135
        assert amcl.frame_id == "map"
        odom = read_bag_trajectory(bag, "/odom")
        assert len(odom) == 2639
        assert (odom.frame_id, odom.child_frame_id) == ("odom", "base_link")

    def test_nav2_tf_chain(self, public_data):
        """tf:map:base_link composes map->odom->base_link and stays close to AMCL."""
        bag = public_data / "nav2_turtlebot.mcap"
        chain = read_bag_trajectory(bag, "tf:map:base_link")
        direct = read_bag_trajectory(bag, "tf:odom:base_link")
        assert 2400 < len(chain) <= len(direct) == 2639
        amcl = read_bag_trajectory(bag, "/amcl_pose")
        # AMCL's pose and the map -> base_link chain describe the same robot.
        idx = np.searchsorted(chain.stamps_ns, amcl.stamps_ns).clip(0, len(chain) - 1)
        close = np.abs(chain.stamps_ns[idx] - amcl.stamps_ns) < 50_000_000
        gap = np.linalg.norm(chain.positions_xyz[idx[close]] - amcl.positions_xyz[close], axis=1)
        assert np.median(gap) < 0.2

    def test_tf_example_ros1_and_ros2_agree(self, public_data):
        """tf_example.bag and tf_example/ give the same odom->base_link chain to 1e-9."""
        ros1 = read_bag_trajectory(public_data / "tf_example.bag", "tf:odom:base_link")
        ros2 = read_bag_trajectory(public_data / "tf_example", "tf:odom:base_link")
        assert len(ros1) == len(ros2) == 517
        np.testing.assert_array_equal(ros1.stamps_ns, ros2.stamps_ns)
        np.testing.assert_allclose(ros1.positions_xyz, ros2.positions_xyz, atol=1e-9)
        assert ros1.quat_xyzw is not None
        assert ros2.quat_xyzw is not None
        np.testing.assert_allclose(ros1.quat_xyzw, ros2.quat_xyzw, atol=1e-9)
        # The chain is information, not a warning (issue 30 item 12).
        assert any("base_footprint → base_link" in n for n in ros1.notes)
        assert not ros1.warnings

    def test_tf_example_static_link_applied(self, public_data):
        """odom->base_link differs from odom->base_footprint by the static link."""
        bag = public_data / "tf_example.bag"
        offset = read_bag_static_transform(bag, "base_footprint", "base_link")
        foot = read_bag_trajectory(bag, "tf:odom:base_footprint")
        base = read_bag_trajectory(bag, "tf:odom:base_link")
        np.testing.assert_allclose(
            base.positions_xyz, foot.with_body_offset(offset).positions_xyz, atol=1e-12
        )

    def test_zipped_public_bag_directory(self, public_data, tmp_path):
        """The tf_example/ folder zipped reads like the folder."""
        copy = tmp_path / "tf_example"
        shutil.copytree(public_data / "tf_example", copy)
        archive = bf.zip_directory(copy, tmp_path / "tf_example.zip")
        traj = read_bag_trajectory(archive, "tf:odom:base_link")
        assert len(traj) == 517


class TestConvertedErrors:
    """Damage reported by a library is a user's error; loceval's own mistakes stay bugs."""

    def test_library_key_error_reads_as_a_damaged_bag(self) -> None:
        """A KeyError raised inside a library (here the standard library's os) is damage."""
        with (
            pytest.raises(ReaderError, match=r"'x.bag' cannot be read.*KeyError"),
            converted("x.bag"),
        ):
            os.environ["LOCEVAL_NO_SUCH_VARIABLE_" + "X" * 8]

    @pytest.mark.parametrize("error", [KeyError, TypeError, AssertionError, RuntimeError])
    def test_our_own_bug_is_not_called_damage(self, error: type[Exception]) -> None:
        """A KeyError, TypeError, AssertionError or RuntimeError raised by our code passes."""

        def buggy() -> None:
            raise error("a bug")  # noqa: EM101, TRY003

        with pytest.raises(error, match="a bug"), converted("x.bag"):
            buggy()

    def test_struct_error_from_our_parser_is_damage(self) -> None:
        """Bytes cut short (struct.error) are damage wherever they are unpacked."""
        with pytest.raises(ReaderError, match="truncated, damaged"), converted("x.bag"):
            struct.unpack("<I", b"\x00")
