"""Format detection from content (loceval.readers.sniff)."""

from __future__ import annotations

from pathlib import Path

import pytest

from loceval.errors import ReaderError
from loceval.readers import TrajectoryFormat, sniff_format
from tests.factories import (
    make_trajectory,
    write_csv,
    write_euroc,
    write_kitti,
    write_motive,
    write_tum,
)

F = TrajectoryFormat


class TestSniffFormat:
    def test_tum(self, tmp_path, rng):
        """TUM lines are told from content, whatever the suffix."""
        assert sniff_format(write_tum(tmp_path / "a.csv", make_trajectory(rng, 5))) is F.TUM

    def test_tum_position_only_and_tabs(self, tmp_path):
        """``t x y`` lines and tab-separated TUM are TUM."""
        path = tmp_path / "a"
        path.write_text("1\t2\t3\n2\t3\t4\n")
        assert sniff_format(path) is F.TUM

    def test_euroc_with_header(self, tmp_path, rng):
        """A ``#timestamp`` header with p_RS_R_x is EuRoC."""
        assert sniff_format(write_euroc(tmp_path / "a.txt", make_trajectory(rng, 5))) is F.EUROC

    def test_euroc_without_header(self, tmp_path):
        """Comma-separated rows of 8+ with integer stamps are EuRoC."""
        path = tmp_path / "a"
        path.write_text("1403715524907143168,0,0,0,1,0,0,0\n")
        assert sniff_format(path) is F.EUROC

    def test_kitti(self, tmp_path, rng):
        """Rows of 12 numbers are KITTI."""
        assert sniff_format(write_kitti(tmp_path / "a.csv", make_trajectory(rng, 5))) is F.KITTI

    def test_csv_with_header(self, tmp_path, rng):
        """A header over comma-separated numbers is a generic CSV."""
        assert sniff_format(write_csv(tmp_path / "a.txt", make_trajectory(rng, 5))) is F.CSV

    def test_csv_whitespace_header_and_hash_header(self, tmp_path):
        """``t x y`` over numbers, and ``#t,x,y`` over numbers, are generic CSV."""
        a, b = tmp_path / "a", tmp_path / "b"
        a.write_text("t x y\n1 2 3\n")
        b.write_text("#t,x,y\n1,2,3\n")
        assert sniff_format(a) is F.CSV
        assert sniff_format(b) is F.CSV

    def test_motive(self, tmp_path, rng):
        """A Format Version first line is Motive."""
        path = write_motive(tmp_path / "a.txt", {"b": make_trajectory(rng, 5)})
        assert sniff_format(path) is F.MOTIVE

    @pytest.mark.parametrize(
        "magic", [b"#ROSBAG V2.0\n", b"\x89MCAP0\r\n", b"SQLite format 3\x00", b"PK\x03\x04"]
    )
    def test_bag_magic(self, tmp_path, magic):
        """ROS 1, MCAP, sqlite3 and zip files are bags by their magic bytes."""
        path = tmp_path / "x.txt"
        path.write_bytes(magic + b"\x00" * 32)
        assert sniff_format(path) is F.BAG

    def test_bag_directory(self, tmp_path):
        """A folder with metadata.yaml is a ROS 2 bag."""
        (tmp_path / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
        assert sniff_format(tmp_path) is F.BAG

    def test_metadata_yaml_file(self, tmp_path):
        """A ROS 2 bag's metadata.yaml names the bag."""
        path = tmp_path / "metadata.yaml"
        path.write_text("rosbag2_bagfile_information: {}\n")
        assert sniff_format(path) is F.BAG

    def test_plain_directory(self, tmp_path):
        """A folder without metadata.yaml is refused."""
        with pytest.raises(ReaderError, match=r"is a folder without a metadata\.yaml"):
            sniff_format(tmp_path)

    @pytest.mark.parametrize(
        "content",
        [
            b"hello world\n",
            b"1 2 3 4 5\n",
            b"1,2,3\n",
            b"\x00\x01binary",
        ],
    )
    def test_unknown_content(self, tmp_path, content):
        """Content matching no format asks for a prefix."""
        path = tmp_path / "x"
        path.write_bytes(content)
        with pytest.raises(ReaderError, match=r"Cannot tell the format of '.*x' .* e\.g\. tum:"):
            sniff_format(path)

    @pytest.mark.parametrize(
        ("content", "what"),
        [(b"", "empty"), (b"\n\n", "empty but for whitespace"), (b" \t\r\n", "empty but")],
    )
    def test_empty_content(self, tmp_path, content, what):
        """An empty or whitespace-only file is called empty, not of an unknown format."""
        path = tmp_path / "x"
        path.write_bytes(content)
        with pytest.raises(ReaderError, match=rf"'.*x' is {what}.*; give the file that holds"):
            sniff_format(path)

    def test_comments_only(self, tmp_path):
        """A file of comments only is said to hold no data rows."""
        path = tmp_path / "x"
        path.write_bytes(b"# only\n\n# timestamp tx ty tz\n")
        with pytest.raises(ReaderError, match=r"'.*x' holds only comments .*, no data rows"):
            sniff_format(path)

    def test_missing(self, tmp_path):
        """A missing file is named."""
        with pytest.raises(ReaderError, match=r"No such file: '.*nope'; check the path\."):
            sniff_format(tmp_path / "nope")

    def test_long_first_chunk(self, tmp_path):
        """A file larger than the sniffed head is told from its complete lines."""
        path = tmp_path / "big"
        path.write_text("".join(f"{i}.5 1.25 2.5 3.75\n" for i in range(20000)))
        assert sniff_format(path) is F.TUM


@pytest.mark.public_data
@pytest.mark.parametrize(
    ("file", "fmt"),
    [
        ("fr2_desk_groundtruth.txt", F.TUM),
        ("fr2_desk_ORB.txt", F.TUM),
        ("freiburg1_xyz-groundtruth.txt", F.TUM),
        ("freiburg1_xyz-rgbdslam.txt", F.TUM),
        ("V102.txt", F.TUM),
        ("V102_groundtruth.csv", F.EUROC),
        ("KITTI_00_gt.txt", F.KITTI),
        ("KITTI_00_ORB.txt", F.KITTI),
        ("KITTI_00_SPTAM.txt", F.KITTI),
        ("motive_take_sample.csv", F.MOTIVE),
        ("ROS_example.bag", F.BAG),
        ("tf_example.bag", F.BAG),
        ("tf_example", F.BAG),
        ("nav2_turtlebot.mcap", F.BAG),
    ],
)
def test_public_files(public_data: Path, file, fmt):
    """Every public recording is told correctly from its content."""
    assert sniff_format(public_data / file) is fmt
