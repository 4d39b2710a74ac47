"""Ranges from a bag topic of sensor_msgs/msg/Range (frame_id names the anchor), and the
header sniffing that tells anchors and ranges tables apart."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from loceval.errors import ReaderError
from loceval.inspection import inspect
from loceval.readers.radio import sniff_radio_table
from loceval.readers.rosbag import StampSource, read_range_topic
from tests import bagfactory as bf
from tests.radio_factory import make_anchors, make_ranges, write_anchors_csv, write_ranges_csv


def _range_records(
    rng: np.random.Generator, *, extra: list[bf.Record] | None = None
) -> tuple[list[bf.Record], np.ndarray, np.ndarray, np.ndarray]:
    """Return Range messages of the generated ranges (received 1 ms after their stamp)."""
    ranges = make_ranges(rng, end_s=5.0).ranges
    ids = np.array(ranges.anchors.ids)[ranges.anchor_index]
    records = [
        bf.Record("/uwb/range", bf.RANGE, int(t) + 1_000_000, (int(t), float(r)), frame_id=str(i))
        for t, r, i in zip(ranges.stamps_ns, ranges.range_m, ids, strict=True)
    ]
    return records + (extra or []), ranges.stamps_ns, ranges.anchor_index, ranges.range_m


@pytest.mark.parametrize("fmt", bf.FORMATS)
def test_range_topic_round_trip(tmp_path: Path, rng: np.random.Generator, fmt: str) -> None:
    """Every message comes back: header stamp, the anchor of its frame id, the float32 range."""
    records, stamps, index, values = _range_records(rng)
    path = bf.write_bag(bf.bag_path(tmp_path, fmt), records, fmt=fmt)
    ranges = read_range_topic(path, "/uwb/range", make_anchors())
    np.testing.assert_array_equal(ranges.stamps_ns, stamps)
    np.testing.assert_array_equal(ranges.anchor_index, index)
    np.testing.assert_allclose(ranges.range_m, values, rtol=1e-7)  # float32 in the message
    assert ranges.warnings == ()
    received = read_range_topic(path, "uwb/range", make_anchors(), stamp=StampSource.RECEIVE)
    np.testing.assert_array_equal(received.stamps_ns, stamps + 1_000_000)


def test_bad_messages_are_dropped_and_counted(tmp_path: Path, rng: np.random.Generator) -> None:
    """NaN, negative and unknown-anchor messages are dropped, counted per reason, named."""
    t = 1_700_000_001_000_000_000
    bad = [
        bf.Record("/uwb/range", bf.RANGE, t, (t, float("nan")), frame_id="A01"),
        bf.Record("/uwb/range", bf.RANGE, t, (t, -2.0), frame_id="A02"),
        bf.Record("/uwb/range", bf.RANGE, t, (t, 3.0), frame_id="uwb_tag"),
    ]
    records, stamps, _, _ = _range_records(rng, extra=bad)
    path = bf.write_bag(bf.bag_path(tmp_path, "mcap"), records, fmt="mcap")
    ranges = read_range_topic(path, "/uwb/range", make_anchors())
    assert len(ranges) == stamps.size
    (warning,) = ranges.warnings
    assert f"3 of {stamps.size + 3} range messages dropped" in warning
    assert "1 whose range is NaN or infinite; 1 with a negative range; " in warning
    assert "1 whose frame id is no anchor id ('uwb_tag')" in warning


def test_wrong_topic_and_type_are_errors(tmp_path: Path, rng: np.random.Generator) -> None:
    """A missing topic lists the Range topics; a topic of another type says so."""
    records, _, _, _ = _range_records(rng)
    poses = bf.random_poses(rng, 5, dt_ns=10_000_000)
    records += bf.pose_records("/pose", bf.POSE, poses)
    path = bf.write_bag(bf.bag_path(tmp_path, "sqlite3"), records, fmt="sqlite3")
    with pytest.raises(ReaderError, match=r"not in bag .*Range topics: /uwb/range"):
        read_range_topic(path, "/uwb/ranges", make_anchors())
    with pytest.raises(ReaderError, match=r"'/pose' .* has type geometry_msgs/msg/PoseStamped"):
        read_range_topic(path, "/pose", make_anchors())


def test_no_usable_message_is_an_error(tmp_path: Path) -> None:
    """Only messages of unknown anchors: an error naming the frame ids."""
    t = 1_700_000_001_000_000_000
    records = [
        bf.Record("/uwb/range", bf.RANGE, t + k, (t + k, 2.0), frame_id="tag") for k in range(3)
    ]
    path = bf.write_bag(bf.bag_path(tmp_path, "rosbag1"), records, fmt="rosbag1")
    with pytest.raises(ReaderError, match=r"none of the 3 range messages is usable .*'tag'"):
        read_range_topic(path, "/uwb/range", make_anchors())


def test_sniff_and_inspect_radio_tables(tmp_path: Path, rng: np.random.Generator) -> None:
    """Headers tell anchors from ranges; the inspection lists the anchor ids."""
    anchors = write_anchors_csv(tmp_path / "a.csv", make_anchors())
    ranges = write_ranges_csv(tmp_path / "r.csv", make_ranges(rng, end_s=2.0).ranges)
    assert sniff_radio_table(anchors) == "anchors"
    assert sniff_radio_table(ranges) == "ranges"
    other = tmp_path / "o.csv"
    other.write_text("# comment\nt_ns;anchor;distance\n1;A01;2.0\n")
    assert sniff_radio_table(other) == "ranges"
    trajectory = tmp_path / "t.csv"
    trajectory.write_text("t,x,y,z\n0.0,1,2,3\n")
    assert sniff_radio_table(trajectory) is None
    assert sniff_radio_table(tmp_path / "missing.csv") is None
    described = inspect(anchors).to_dict()
    # a survey id,x,y,z is inspected as surveyed points: control points or a radio's anchors
    assert described["kind"] == "points"
    assert described["ids"] == list(make_anchors().ids)
    described = inspect(ranges).to_dict()
    assert described["kind"] == "ranges"
    assert described["ranges"] == len(ranges.read_text().splitlines()) - 1
    assert described["anchor_ids"][0] == "A01"
