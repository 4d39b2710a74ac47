"""Tests for loceval.inspection: what a bag holds and which trajectories it offers."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from loceval.errors import ReaderError
from loceval.inspection import format_inspection, inspect, inspect_recording
from loceval.readers.rosbag import read_bag_trajectory
from tests import bagfactory as bf

NS = bf.NS
T0 = bf.T0_NS


@pytest.fixture
def records(rng: np.random.Generator) -> list[bf.Record]:
    """A robot with AMCL, odometry, a growing path, tf (map -> odom -> base_link) and images."""
    odom = bf.random_poses(rng, 50, dt_ns=NS // 10)
    base = bf.random_poses(rng, 150, dt_ns=NS // 30)
    amcl = bf.random_poses(rng, 12, dt_ns=NS // 2)
    return [
        *bf.pose_records("/amcl_pose", bf.POSE_COV, amcl),
        *bf.pose_records("/odom", bf.ODOMETRY, base, frame_id="odom"),
        *bf.path_records("/plan", base, cuts=[40, 90]),
        *bf.tf_records(bf.link_transforms("map", "odom", odom)),
        *bf.tf_records(bf.link_transforms("odom", "base_link", base)),
        *bf.tf_records(
            [
                bf.Tf(T0, "base_link", "camera", (0.1, 0, 0.2), (0, 0, 0, 1)),
                bf.Tf(T0, "camera", "camera_optical", (0, 0, 0), Rotation.identity().as_quat()),
            ],
            topic="/tf_static",
        ),
        *[bf.image_record("/camera/image", T0 + i * NS // 15) for i in range(60)],
        bf.Record("/imu", bf.IMU, T0 + NS, (T0 + NS, (0, 0, 0), (0, 0, 0, 1))),
    ]


@pytest.mark.parametrize("fmt", bf.FORMATS)
def test_lists_topics_tree_and_sources(tmp_path, records, fmt):
    """Topics, the tf tree with rates, and the trajectory sources with their selectors."""
    bag = bf.write_bag(bf.bag_path(tmp_path, fmt), records, fmt=fmt)
    insp = inspect_recording(bag)
    assert insp.storage_format == {"rosbag1": "rosbag1", "sqlite3": "rosbag2-sqlite3"}.get(
        fmt, "rosbag2-mcap"
    )
    topics = {t.name: t for t in insp.topics}
    assert topics["/camera/image"].message_count == 60
    assert not topics["/camera/image"].pose_source
    assert topics["/amcl_pose"].pose_source
    assert not topics["/tf"].pose_source
    frames = {f.frame: f for f in insp.frames}
    assert frames["map"].parent == ""
    assert frames["odom"].rate_hz == pytest.approx(10.0, rel=0.02)
    assert frames["base_link"].rate_hz == pytest.approx(30.0, rel=0.05)
    assert frames["base_link"].message_count == 150
    assert frames["camera_optical"].static
    assert frames["camera_optical"].depth == 4
    sources = {c.selector: c for c in insp.candidates}
    assert set(sources) >= {
        "/amcl_pose",
        "/odom",
        "/plan",
        "tf:map:odom",
        "tf:odom:base_link",
        "tf:map:base_link",
    }
    assert "/imu" not in sources
    assert "/camera/image" not in sources
    assert sources["/amcl_pose"].pose_count == 12
    assert sources["/plan"].pose_count == 90
    assert sources["tf:map:base_link"].description == "map → odom → base_link"
    assert insp.duration_s > 4.0


def test_counts_and_ranges_match_reading(tmp_path, records):
    """A source's pose count and time range are what reading it gives."""
    bag = bf.write_bag(tmp_path / "rec", records, fmt="mcap")
    insp = inspect_recording(bag)
    for candidate in insp.candidates:
        traj = read_bag_trajectory(bag, candidate.selector)
        assert len(traj) == candidate.pose_count, candidate.selector
        assert candidate.first_stamp_ns == traj.stamps_ns[0]
        assert candidate.last_stamp_ns == traj.stamps_ns[-1]


def test_inspect_sniffs_bags_and_rates(tmp_path, records):
    """inspect() on a bag gives inspect_recording's result, with rates and orientation."""
    bag = bf.write_bag(tmp_path / "rec", records, fmt="mcap")
    insp = inspect(str(bag))
    assert insp == inspect_recording(bag)
    assert (insp.kind, insp.format) == ("rosbag2-mcap", "bag")
    sources = {c.selector: c for c in insp.sources}
    # /amcl_pose: 12 poses 0.5 s apart (+ < 1 ms jitter), so 11 intervals over ~5.5 s.
    assert sources["/amcl_pose"].rate_hz == pytest.approx(2.0, rel=0.01)
    assert sources["/amcl_pose"].orientation is True
    # tf:odom:base_link is sampled at base_link's 30 Hz (NS // 30 apart, jittered).
    assert sources["tf:odom:base_link"].rate_hz == pytest.approx(30.0, rel=0.05)
    data = insp.to_dict()
    assert data["kind"] == "rosbag2-mcap"
    assert "poses" not in data  # a bag is no single trajectory


@pytest.mark.parametrize("fmt", bf.FORMATS)
def test_image_payloads_are_never_read(tmp_path, records, fmt, monkeypatch):
    """Inspection deserializes no image (a deserializer that fails on images is never hit)."""
    from rosbags.highlevel import AnyReader

    original = AnyReader.deserialize
    deserialized: list[str] = []

    def recorded(self, rawdata, typ):
        deserialized.append(typ)  # the reader converts errors raised here: record, not assert
        return original(self, rawdata, typ)

    monkeypatch.setattr(AnyReader, "deserialize", recorded)
    bag = bf.write_bag(bf.bag_path(tmp_path, fmt), records, fmt=fmt)
    insp = inspect_recording(bag)
    assert bf.IMAGE not in deserialized
    assert insp.sources  # the poses were still found


def test_to_dict_is_json(tmp_path, records):
    """to_dict() is plain JSON with stamps as integer nanoseconds."""
    bag = bf.write_bag(tmp_path / "rec", records, fmt="sqlite3")
    data = json.loads(json.dumps(inspect_recording(bag).to_dict()))
    assert data["storage_format"] == "rosbag2-sqlite3"
    assert data["archive"] is None
    assert isinstance(data["start_ns"], int)
    assert {s["selector"] for s in data["sources"]} >= {"/odom", "tf:map:base_link"}
    assert any(f["frame"] == "camera" and f["static"] for f in data["tf_tree"])


def test_format_for_terminal(tmp_path, records):
    """The terminal text shows the tree indented and the selectors to type."""
    bag = bf.write_bag(tmp_path / "rec", records, fmt="mcap")
    text = format_inspection(inspect_recording(bag))
    assert "(rosbag2-mcap)" in text
    assert "\n  map\n    odom  (10.0 Hz, 50 transforms" in text
    assert "        camera  (static)" in text
    assert "tf:map:base_link" in text
    assert "2023-11-14T22:13:20" in text


def test_zipped_bag(tmp_path, records):
    """A zipped bag is inspected, and says it was zipped."""
    bag = bf.write_bag(tmp_path / "rec", records, fmt="mcap")
    insp = inspect_recording(bf.zip_directory(bag, tmp_path / "rec.zip"))
    assert insp.archive == "zip"
    assert "zipped" in format_inspection(insp)
    assert any(c.selector == "tf:map:base_link" for c in insp.candidates)


def test_broken_tree_is_a_warning(tmp_path, rng):
    """A frame with two parents is reported as a warning, not an error."""
    a = bf.random_poses(rng, 20, dt_ns=NS // 10)
    records = bf.tf_records(bf.link_transforms("map", "base", a)) + bf.tf_records(
        bf.link_transforms("odom", "base", a)
    )
    bag = bf.write_bag(tmp_path / "rec", records, fmt="mcap")
    insp = inspect_recording(bag)
    assert any("'base' has 2 parents" in w for w in insp.warnings)
    assert "warnings:" in format_inspection(insp)


def test_bag_without_sources(tmp_path):
    """A bag with only images lists no sources and says so."""
    records = [bf.image_record("/camera/image", T0 + i * NS) for i in range(3)]
    bag = bf.write_bag(tmp_path / "rec", records, fmt="mcap")
    insp = inspect_recording(bag)
    assert insp.candidates == ()
    text = format_inspection(insp)
    assert "(no tf data)" in text
    assert "(none: no pose topic" in text


def test_unreadable_bag(tmp_path):
    """Inspecting a damaged bag is a ReaderError."""
    path = tmp_path / "broken.mcap"
    path.write_bytes(b"\x89MCAP0\r\n" + bytes(64))
    with pytest.raises(ReaderError, match="cannot be read"):
        inspect_recording(path)


def test_import_does_not_load_rosbags():
    """Importing loceval.inspection does not import rosbags."""
    code = "import sys, loceval.inspection; print('rosbags' in sys.modules)"
    root = Path(__file__).resolve().parents[3]
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=root
    )
    assert out.stdout.strip() == "False"


def test_tf_sources_most_useful_first(tmp_path, records, rng):
    """Fixed frame -> robot first, then fixed -> robot part, fixed -> fixed, inside the robot."""
    wheel = bf.random_poses(rng, 30, dt_ns=NS // 20)
    records = [*records, *bf.tf_records(bf.link_transforms("base_link", "left_wheel", wheel))]
    bag = bf.write_bag(bf.bag_path(tmp_path, "mcap"), records, fmt="mcap")
    insp = inspect_recording(bag)
    tf_sources = [c.selector for c in insp.candidates if c.kind == "tf"]
    assert tf_sources == [
        "tf:map:base_link",  # group 0: fixed -> robot, map before odom
        "tf:odom:base_link",
        "tf:map:left_wheel",  # group 1: fixed -> a part of the robot (from the root only)
        "tf:map:odom",  # group 2: fixed -> fixed
        "tf:base_link:left_wheel",  # group 3: inside the robot
    ]
    assert [c.kind for c in insp.candidates[:3]] == ["topic"] * 3  # topics keep coming first


@pytest.mark.public_data
class TestPublicData:
    def test_nav2(self, public_data):
        """nav2_turtlebot.mcap lists its topics, the map tree and the map -> base_link chain."""
        insp = inspect_recording(public_data / "nav2_turtlebot.mcap")
        assert {t.name for t in insp.topics} == {"/amcl_pose", "/odom", "/tf", "/tf_static"}
        sources = {c.selector: c for c in insp.candidates}
        assert sources["/amcl_pose"].pose_count == 135
        assert sources["/odom"].pose_count == 2639
        assert sources["tf:map:base_link"].description == "map → odom → base_link"
        assert insp.frames[0].frame == "map"

    def test_nav2_lists_the_robot_chain_first(self, public_data):
        """nav2_turtlebot.mcap: map -> base_link leads the tf sources, the wheel links trail."""
        insp = inspect_recording(public_data / "nav2_turtlebot.mcap")
        tf_sources = [c.selector for c in insp.candidates if c.kind == "tf"]
        assert tf_sources == [
            "tf:map:base_link",
            "tf:map:base_footprint",
            "tf:odom:base_link",
            "tf:odom:base_footprint",
            "tf:map:left_wheel",
            "tf:map:right_wheel",
            "tf:map:odom",
            "tf:base_link:left_wheel",
            "tf:base_link:right_wheel",
        ]

    def test_ros_example(self, public_data):
        """ROS_example.bag lists its three PoseStamped topics with their counts."""
        insp = inspect_recording(public_data / "ROS_example.bag")
        counts = {c.selector: c.pose_count for c in insp.candidates}
        assert counts == {"groundtruth": 12765, "ORB-SLAM": 8362, "S-PTAM": 5439}
        assert insp.storage_format == "rosbag1"

    @pytest.mark.parametrize("name", ["tf_example.bag", "tf_example"])
    def test_tf_example(self, public_data, name, tmp_path):
        """tf_example (ROS 1 and ROS 2) lists /tf, /tf_static and tf:odom:base_link."""
        path = public_data / name
        if path.is_dir():
            path = shutil.copytree(path, tmp_path / name)
        insp = inspect_recording(path)
        assert {t.name for t in insp.topics} == {"/tf", "/tf_static"}
        sources = {c.selector: c.pose_count for c in insp.candidates}
        assert sources["tf:odom:base_link"] == 517
        assert [(f.frame, f.parent, f.static) for f in insp.frames] == [
            ("odom", "", False),
            ("base_footprint", "odom", False),
            ("base_link", "base_footprint", True),
        ]
