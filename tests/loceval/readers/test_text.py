"""TUM, EuRoC and KITTI readers, and the shared table parser."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from loceval.errors import ReaderError
from loceval.readers import read_euroc, read_kitti, read_tum
from loceval.readers.text import decode_text, load_text, parse_table
from tests.factories import (
    T0_NS,
    assert_trajectories_close,
    make_trajectory,
    seconds_text,
    write_euroc,
    write_kitti,
    write_tum,
)

# Decimal seconds -> float -> ns is exact to about 0.25 us at epoch scale.
STAMP_ATOL_NS = 500


class TestTum:
    def test_full_poses_round_trip(self, tmp_path, rng):
        """A written TUM file reads back with the same stamps, positions and orientations."""
        truth = make_trajectory(rng, 50)
        read = read_tum(write_tum(tmp_path / "a.txt", truth), name="gt")
        assert_trajectories_close(read, truth, atol_ns=STAMP_ATOL_NS)
        assert read.name == "gt"
        assert read.source == f"tum:{tmp_path / 'a.txt'}"
        assert read.warnings == ()

    def test_position_only_four_columns(self, tmp_path, rng):
        """``t x y z`` lines give a position-only trajectory."""
        truth = make_trajectory(rng, 20, orientation=False)
        read = read_tum(write_tum(tmp_path / "a.txt", truth))
        assert read.quat_xyzw is None
        assert_trajectories_close(read, truth, atol_ns=STAMP_ATOL_NS)

    def test_position_only_three_columns(self, tmp_path, rng):
        """``t x y`` lines give z = 0."""
        truth = make_trajectory(rng, 20, orientation=False, planar=True)
        read = read_tum(write_tum(tmp_path / "a.txt", truth, columns=3))
        assert read.quat_xyzw is None
        assert_trajectories_close(read, truth, atol_ns=STAMP_ATOL_NS)

    def test_comments_blank_lines_crlf_and_bom(self, tmp_path):
        """Comments anywhere, blank lines, CRLF line ends and a UTF-8 BOM are accepted."""
        text = (
            "\ufeff# header\r\n\r\n1.0 0 0 0 0 0 0 1\r\n# mid\r\n"
            "2.0 1 0 0 0 0 0 1 # tail\r\n3.0 2 0 0 0 0 0 1\r\n\r\n"
        )
        path = tmp_path / "a.txt"
        path.write_bytes(text.encode())
        read = read_tum(path)
        assert read.stamps_ns.tolist() == [10**9, 2 * 10**9, 3 * 10**9]
        np.testing.assert_array_equal(read.positions_xyz[:, 0], [0.0, 1.0, 2.0])

    def test_error_line_numbers_count_comments(self, tmp_path):
        """Error messages give the file's line number, counting comment and blank lines."""
        path = tmp_path / "a.txt"
        path.write_text("# c\n1 0 0 0 0 0 0 1\n\n# c\n2 0 0 0 0 0 0 1\n3 nan 0 0 0 0 0 1\n")
        with pytest.raises(ReaderError, match=r"a\.txt, line 6: position is NaN or inf"):
            read_tum(path)

    def test_unsorted_stamps_are_sorted_with_warning(self, tmp_path):
        """Out-of-order lines are sorted and the result says so."""
        path = tmp_path / "a.txt"
        path.write_text("3 2 0 0\n1 0 0 0\n2 1 0 0\n")
        read = read_tum(path)
        assert read.stamps_ns.tolist() == [10**9, 2 * 10**9, 3 * 10**9]
        np.testing.assert_array_equal(read.positions_xyz[:, 0], [0.0, 1.0, 2.0])
        assert any("not in order" in w for w in read.warnings)

    def test_duplicate_stamps_dropped_with_warning(self, tmp_path):
        """A repeated stamp keeps the first pose and the result says so."""
        path = tmp_path / "a.txt"
        path.write_text("1 0 0 0\n2 1 0 0\n2 9 0 0\n3 2 0 0\n")
        read = read_tum(path)
        assert len(read) == 3
        np.testing.assert_array_equal(read.positions_xyz[:, 0], [0.0, 1.0, 2.0])
        assert any("1 pose with a duplicate stamp" in w for w in read.warnings)

    def test_slightly_off_quaternions_are_normalized(self, tmp_path):
        """Quaternions within 1e-3 of unit norm are normalized."""
        path = tmp_path / "a.txt"
        path.write_text("1 0 0 0 0 0 0 1.0005\n2 0 0 0 0 0 0 0.9995\n3 0 0 0 0 0 0 1\n")
        read = read_tum(path)
        assert read.quat_xyzw is not None
        np.testing.assert_allclose(np.linalg.norm(read.quat_xyzw, axis=1), 1.0, atol=1e-12)

    @pytest.mark.parametrize(
        ("line", "pattern"),
        [
            ("3 0 0 0 0 0 0 0", r"a\.txt, line 3: quaternion has norm 0"),
            ("3 0 0 0 0 0 0 2", r"a\.txt, line 3: quaternion has norm 2"),
            ("3 0 0 0 inf 0 0 1", r"a\.txt, line 3: quaternion is NaN or inf"),
            ("3 0 0 0 0 0 0 1 5", r"a\.txt, line 3: 9 values, but line 1 has 8"),
            ("3 0 0 0 0 0 1", r"a\.txt, line 3: 7 values, but line 1 has 8"),
            ("3 0 abc 0 0 0 0 1", r"a\.txt, line 3: 'abc' in column '3' is not a number"),
            ("nan 0 0 0 0 0 0 1", r"a\.txt, line 3: stamp nan s is not a usable time"),
            ("1e300 0 0 0 0 0 0 1", r"a\.txt, line 3: stamp 1e\+300 s is not a usable time"),
        ],
    )
    def test_bad_line_is_named(self, tmp_path, line, pattern):
        """Each kind of bad line gets a ReaderError naming the file and the line."""
        path = tmp_path / "a.txt"
        path.write_text(f"1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n{line}\n4 0 0 0 0 0 0 1\n")
        with pytest.raises(ReaderError, match=pattern):
            read_tum(path)

    def test_wrong_width_everywhere(self, tmp_path):
        """Lines of 5 values are not TUM, whatever their agreement."""
        path = tmp_path / "a.txt"
        path.write_text("1 0 0 0 0\n2 0 0 0 0\n3 0 0 0 0\n")
        with pytest.raises(ReaderError, match=r"a\.txt, line 1: 5 values per line, but every TUM"):
            read_tum(path)

    def test_fewer_than_three_poses(self, tmp_path):
        """Two poses are not enough."""
        path = tmp_path / "a.txt"
        path.write_text("1 0 0 0\n2 0 0 0\n")
        with pytest.raises(ReaderError, match=r"a\.txt: 2 poses, but at least 3 are needed"):
            read_tum(path)

    def test_empty_file(self, tmp_path):
        """A file of comments only has no poses."""
        path = tmp_path / "a.txt"
        path.write_text("# nothing\n\n")
        with pytest.raises(ReaderError, match=r"a\.txt holds no poses .*only a header or comments"):
            read_tum(path)

    def test_missing_file(self, tmp_path):
        """A missing file names the path and says to check it."""
        with pytest.raises(ReaderError, match=r"^No such file: '.*nope\.txt'; check the path\.$"):
            read_tum(tmp_path / "nope.txt")

    def test_folder(self, tmp_path):
        """A folder is not a trajectory file."""
        with pytest.raises(ReaderError, match=r"is a folder, not a trajectory file"):
            read_tum(tmp_path)

    def test_binary_file(self, tmp_path):
        """A binary file is refused with a hint about bags."""
        path = tmp_path / "a.txt"
        path.write_bytes(b"\x00\x01\x02" * 10)
        with pytest.raises(ReaderError, match=r"is a binary file, not a text trajectory"):
            read_tum(path)

    def test_latin1_comment(self, tmp_path):
        """A non-UTF-8 comment does not stop the reader."""
        path = tmp_path / "a.txt"
        path.write_bytes(b"# M\xfcnchen\n1 0 0 0\n2 0 0 0\n3 0 0 0\n")
        assert len(read_tum(path)) == 3

    @given(
        stamps_us=st.lists(
            st.integers(min_value=0, max_value=4 * 10**15), min_size=3, max_size=30, unique=True
        ),
        data=st.data(),
    )
    def test_round_trip_property(self, tmp_path_factory, stamps_us, data):
        """Any microsecond stamps and finite poses survive write -> read (float seconds)."""
        stamps = [s * 1000 for s in stamps_us]
        n = len(stamps)
        floats = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
        positions = np.array(data.draw(st.lists(floats, min_size=3 * n, max_size=3 * n)))
        rotvecs = np.array(
            data.draw(st.lists(st.floats(-3.0, 3.0), min_size=3 * n, max_size=3 * n))
        ).reshape(n, 3)
        truth = make_trajectory(np.random.default_rng(0), n)
        truth = type(truth)(
            np.sort(np.array(stamps, dtype=np.int64)),
            positions.reshape(n, 3),
            Rotation.from_rotvec(rotvecs).as_quat(),
        )
        path = write_tum(tmp_path_factory.mktemp("tum") / "a.txt", truth)
        read = read_tum(path)
        # float seconds carry ~16 significant digits: 4e9 s -> about 0.5 us
        assert_trajectories_close(read, truth, atol_m=0.0, atol_ns=1000, atol_rad=1e-9)


class TestEuroc:
    def test_reads_w_first_quaternions_and_exact_ns(self, tmp_path, rng):
        """EuRoC rows give exact int64 stamps and x y z w quaternions."""
        truth = make_trajectory(rng, 30, t0_ns=1_403_715_524_907_143_168, dt_ns=5_000_001)
        read = read_euroc(write_euroc(tmp_path / "gt.csv", truth))
        assert_trajectories_close(read, truth)
        assert read.source == f"euroc:{tmp_path / 'gt.csv'}"

    def test_eight_column_estimate(self, tmp_path, rng):
        """Estimate files with only the first eight columns are read."""
        truth = make_trajectory(rng, 10)
        read = read_euroc(write_euroc(tmp_path / "e.csv", truth, extra_columns=False))
        assert_trajectories_close(read, truth)

    def test_header_without_hash_and_position_only(self, tmp_path):
        """A plain header row is skipped, and ``timestamp, x, y, z`` rows are position-only."""
        path = tmp_path / "e.csv"
        path.write_text("timestamp,x,y,z\n1000,1,2,3\n2000,1,2,3\n3000,1,2,3\n")
        read = read_euroc(path)
        assert read.quat_xyzw is None
        assert read.stamps_ns.tolist() == [1000, 2000, 3000]

    def test_float_stamps_are_rounded_with_warning(self, tmp_path):
        """Stamps written as floats are rounded to nanoseconds and the result says so."""
        path = tmp_path / "e.csv"
        path.write_text("1.5e3,0,0,0,1,0,0,0\n2.5e3,0,0,0,1,0,0,0\n3.5e3,0,0,0,1,0,0,0\n")
        read = read_euroc(path)
        assert read.stamps_ns.tolist() == [1500, 2500, 3500]
        assert any("not integer nanoseconds" in w for w in read.warnings)

    @pytest.mark.parametrize(
        ("row", "pattern"),
        [
            ("3000,0,0,0,1,0", r"e\.csv, line 4: 6 cells, but column 'q_y' is cell 7"),
            ("3000,0,x,0,1,0,0,0", r"e\.csv, line 4: 'x' in column 'p_y' is not a number"),
            ("3000,0,0,0,0,0,0,0", r"e\.csv, line 4: quaternion has norm 0"),
            ("3000,0,,0,1,0,0,0", r"e\.csv, line 4: column 'p_y' is empty"),
        ],
    )
    def test_bad_row_is_named(self, tmp_path, row, pattern):
        """Bad EuRoC rows name the file, the line and the column."""
        path = tmp_path / "e.csv"
        path.write_text(
            f"#timestamp,x,y,z,qw,qx,qy,qz\n1000,0,0,0,1,0,0,0\n2000,0,0,0,1,0,0,0\n{row}\n"
        )
        with pytest.raises(ReaderError, match=pattern):
            read_euroc(path)

    def test_too_few_columns(self, tmp_path):
        """Rows of five columns are neither full nor position-only EuRoC."""
        path = tmp_path / "e.csv"
        path.write_text("1,0,0,0,1\n2,0,0,0,1\n3,0,0,0,1\n")
        with pytest.raises(ReaderError, match=r"e\.csv, line 1: 5 columns, but a EuRoC row"):
            read_euroc(path)


class TestKitti:
    def test_without_times_stamps_by_index(self, tmp_path, rng):
        """Without a times file pose i is stamped i seconds, with a warning."""
        truth = make_trajectory(rng, 12)
        read = read_kitti(write_kitti(tmp_path / "00.txt", truth))
        assert read.stamps_ns.tolist() == [i * 10**9 for i in range(12)]
        np.testing.assert_allclose(read.positions_xyz, truth.positions_xyz, atol=1e-12)
        assert read.quat_xyzw is not None
        assert truth.quat_xyzw is not None
        delta = Rotation.from_quat(read.quat_xyzw).inv() * Rotation.from_quat(truth.quat_xyzw)
        np.testing.assert_allclose(delta.magnitude(), 0.0, atol=1e-9)
        assert any("matched by index" in w for w in read.warnings)

    def test_with_times_file(self, tmp_path, rng):
        """A times file gives the stamps and appears in the source."""
        truth = make_trajectory(rng, 12, t0_ns=0, dt_ns=103_735_900)
        times = tmp_path / "times.txt"
        read = read_kitti(write_kitti(tmp_path / "00.txt", truth, times_path=times), times=times)
        assert_trajectories_close(read, truth, atol_m=1e-12, atol_ns=1, atol_rad=1e-9)
        assert read.source == f"kitti:{tmp_path / '00.txt'}@times={times}"
        assert read.warnings == ()

    def test_times_count_mismatch(self, tmp_path, rng):
        """A times file with another number of lines is refused."""
        truth = make_trajectory(rng, 12)
        times = tmp_path / "times.txt"
        poses = write_kitti(tmp_path / "00.txt", truth, times_path=times)
        times.write_text("0\n0.1\n0.2\n")
        with pytest.raises(ReaderError, match=r"times\.txt holds 3 times but .*00\.txt holds 12"):
            read_kitti(poses, times=times)

    def test_times_file_with_two_columns(self, tmp_path, rng):
        """A times file holds one value per line."""
        poses = write_kitti(tmp_path / "00.txt", make_trajectory(rng, 3))
        times = tmp_path / "times.txt"
        times.write_text("0 1\n1 1\n2 1\n")
        with pytest.raises(ReaderError, match=r"times\.txt, line 1: 2 values, but a KITTI times"):
            read_kitti(poses, times=times)

    def test_missing_times_file(self, tmp_path, rng):
        """A missing times file is named."""
        poses = write_kitti(tmp_path / "00.txt", make_trajectory(rng, 3))
        with pytest.raises(ReaderError, match=r"No such file: '.*t\.txt'"):
            read_kitti(poses, times=tmp_path / "t.txt")

    def test_wrong_width(self, tmp_path):
        """Lines of 8 values are not KITTI poses."""
        path = tmp_path / "00.txt"
        path.write_text("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n3 0 0 0 0 0 0 1\n")
        with pytest.raises(
            ReaderError, match=r"00\.txt, line 1: 8 values per line, but every KITTI"
        ):
            read_kitti(path)

    def test_non_rotation_is_named(self, tmp_path):
        """A 3x3 block far from a rotation names its line."""
        ok = "1 0 0 0 0 1 0 0 0 0 1 0"
        path = tmp_path / "00.txt"
        path.write_text(f"{ok}\n{ok}\n2 0 0 0 0 1 0 0 0 0 1 0\n")
        with pytest.raises(ReaderError, match=r"00\.txt, line 3: the 3x3 block is not a rotation"):
            read_kitti(path)

    def test_nan_pose_is_named(self, tmp_path):
        """A NaN in a pose names its line."""
        ok = "1 0 0 0 0 1 0 0 0 0 1 0"
        path = tmp_path / "00.txt"
        path.write_text(f"{ok}\nnan 0 0 0 0 1 0 0 0 0 1 0\n{ok}\n")
        with pytest.raises(ReaderError, match=r"00\.txt, line 2: the pose holds NaN or inf"):
            read_kitti(path)

    def test_print_rounding_is_projected(self, tmp_path):
        """Rotations off by print rounding (1e-6) are accepted and made orthonormal."""
        c, s = np.cos(0.3), np.sin(0.3)
        row = f"{c + 1e-6:.7f} {-s:.7f} 0 1 {s:.7f} {c:.7f} 0 2 0 0 1.000001 3"
        path = tmp_path / "00.txt"
        path.write_text(f"{row}\n{row}\n{row}\n")
        read = read_kitti(path)
        assert read.quat_xyzw is not None
        np.testing.assert_allclose(
            Rotation.from_quat(read.quat_xyzw[0]).as_euler("xyz"), [0, 0, 0.3], atol=1e-5
        )


class TestParseTable:
    def test_fast_and_slow_paths_agree(self):
        """The C parser and the line-by-line pass give the same values and line numbers."""
        text = "# h\n1 2 3\n\n4 5 6 # c\n7 8 9\n"
        fast = parse_table(text, where="f", delimiter=None, hint="h", comments="#")
        slow = parse_table(text + "1_0 1 1\n", where="f", delimiter=None, hint="h", comments="#")
        np.testing.assert_array_equal(fast.values, slow.values[:3])
        assert fast.lines.tolist() == [2, 4, 5]
        assert slow.lines.tolist() == [2, 4, 5, 6]

    def test_empty_cells_become_nan_rows(self):
        """With empty cells allowed, their rows are flagged instead of rejected."""
        text = "a,b,c\n1,2,3\n4,,6\n,8,9\n10,11,\n"
        table = parse_table(
            text,
            where="f",
            delimiter=",",
            hint="h",
            skip_lines=1,
            usecols=[0, 1, 2],
            empty_cells=True,
        )
        assert table.empty.tolist() == [False, True, True, True]
        assert table.lines.tolist() == [2, 3, 4, 5]

    def test_literal_nan_is_not_an_empty_cell(self):
        """A written NaN stays NaN and is not flagged as an empty cell."""
        text = "1,2,3\n4,nan,6\n7,,9\n"
        table = parse_table(
            text, where="f", delimiter=",", hint="h", usecols=[0, 1, 2], empty_cells=True
        )
        assert table.empty.tolist() == [False, False, True]
        assert np.isnan(table.values[1, 1])

    def test_int_first_is_exact(self):
        """The first column is parsed as exact int64 when asked for."""
        text = "1403715524907143168,1\n1403715524907143169,2\n"
        table = parse_table(
            text, where="f", delimiter=",", hint="h", usecols=[0, 1], int_first=True
        )
        assert table.first_int is not None
        assert table.first_int.tolist() == [1403715524907143168, 1403715524907143169]

    @pytest.mark.parametrize(
        "raw",
        [
            b"# t x y z\n\n1 0 0 0\n2 1.5 0 0\n3 2 0 .5\n",  # plain ASCII: read as bytes
            b"\xef\xbb\xbf# header\r\n1 0 0 0\r\n2 1 0 0\r\n3 2 0 0\r\n",  # BOM, CRLF
            b"# M\xfcnchen\n1 0 0 0\n2 0 0 0\n3 0 0 0\n",  # Latin-1: decoded first
            b"1 0 0 0\r2 0 0 0\r3 0 0 0\r",  # CR-only line ends: decoded first
            b"# c\n1 0 0 0\n\n# mid\n2 0 0 0 # tail\n3 1e-3 0 0\n",  # comments below
        ],
    )
    def test_bytes_parse_as_their_text(self, raw: bytes):
        """A table given as the file's bytes equals the one parsed from its decoded text."""
        from_text = parse_table(decode_text(raw), where="f", delimiter=None, hint="h", comments="#")
        from_bytes = parse_table(raw, where="f", delimiter=None, hint="h", comments="#")
        np.testing.assert_array_equal(from_bytes.values, from_text.values)
        np.testing.assert_array_equal(from_bytes.lines, from_text.lines)
        assert len(from_bytes) == 3

    def test_bytes_errors_name_the_line_as_text_does(self):
        """A bad cell in bytes is reported with its file line, as from the text."""
        raw = b"# c\n1 0 0 0\n2 x 0 0\n"
        with pytest.raises(ReaderError, match=r"f, line 3") as from_bytes:
            parse_table(raw, where="f", delimiter=None, hint="h", comments="#")
        with pytest.raises(ReaderError) as from_text:
            parse_table(raw.decode(), where="f", delimiter=None, hint="h", comments="#")
        assert str(from_bytes.value) == str(from_text.value)

    def test_load_text_old_mac_line_ends(self, tmp_path):
        """CR-only line ends become LF."""
        path = tmp_path / "a.txt"
        path.write_bytes(b"1 0 0 0\r2 0 0 0\r3 0 0 0\r")
        assert load_text(path).count("\n") == 3


def test_seconds_text_is_exact():
    """The factory writes nanosecond stamps as exact decimal seconds."""
    assert seconds_text(T0_NS + 1) == "1700000000.000000001"
    assert seconds_text(-1_500_000_000) == "-1.500000000"


@pytest.mark.public_data
class TestPublicData:
    @pytest.mark.parametrize(
        ("file", "poses", "orientation"),
        [
            ("fr2_desk_groundtruth.txt", 20956, True),
            ("fr2_desk_ORB.txt", 2893, True),
            ("freiburg1_xyz-groundtruth.txt", 3000, True),
            ("freiburg1_xyz-rgbdslam.txt", 788, True),
            ("V102.txt", 803, True),
        ],
    )
    def test_tum_pose_counts(self, public_data: Path, file, poses, orientation):
        """The public TUM files read with their known pose counts."""
        read = read_tum(public_data / file)
        assert len(read) == poses
        assert read.has_orientation is orientation

    def test_tum_duplicates_are_reported(self, public_data: Path):
        """fr2_desk ground truth repeats one stamp and V102.txt four; both are reported."""
        fr2 = read_tum(public_data / "fr2_desk_groundtruth.txt")
        v102 = read_tum(public_data / "V102.txt")
        assert any("1 pose with a duplicate stamp" in w for w in fr2.warnings)
        assert any("4 poses with a duplicate stamp" in w for w in v102.warnings)

    def test_euroc_ground_truth(self, public_data: Path):
        """V102 ground truth: 16702 poses, exact first stamp, w-first quaternion converted."""
        read = read_euroc(public_data / "V102_groundtruth.csv")
        assert len(read) == 16702
        assert int(read.stamps_ns[0]) == 1403715524907143168
        assert read.quat_xyzw is not None
        np.testing.assert_allclose(
            read.quat_xyzw[0], np.array([0.789985, -0.205376, 0.554528, 0.161996]), atol=1e-5
        )

    @pytest.mark.parametrize("file", ["KITTI_00_gt.txt", "KITTI_00_ORB.txt", "KITTI_00_SPTAM.txt"])
    def test_kitti_without_times(self, public_data: Path, file):
        """The KITTI 00 files hold 4541 poses each, stamped by index."""
        read = read_kitti(public_data / file)
        assert len(read) == 4541
        assert int(read.stamps_ns[-1]) == 4540 * 10**9

    def test_kitti_with_times(self, public_data: Path):
        """KITTI 00 ground truth with its times file ends at the last time."""
        read = read_kitti(
            public_data / "KITTI_00_gt.txt", times=public_data / "KITTI_00_gt_times.txt"
        )
        assert len(read) == 4541
        assert read.warnings == ()
        last = (public_data / "KITTI_00_gt_times.txt").read_text().split()[-1]
        assert abs(int(read.stamps_ns[-1]) - float(last) * 1e9) < 1e3

    @pytest.mark.parametrize("file", ["KITTI_00_gt.txt", "KITTI_00_ORB.txt"])
    def test_kitti_quaternions_match_scipy(self, public_data: Path, file):
        """KITTI's printed matrices give scipy's quaternions (the oracle), rounding included."""
        read = read_kitti(public_data / file)
        matrices = np.loadtxt(public_data / file).reshape(-1, 3, 4)[:, :, :3]
        assert read.quat_xyzw is not None
        np.testing.assert_allclose(
            read.quat_xyzw, Rotation.from_matrix(matrices).as_quat(), rtol=0.0, atol=1e-15
        )


def test_tum_positions_beyond_any_site_name_the_line(tmp_path: Path) -> None:
    """A TUM line with a 1e160 m coordinate is refused with its line number."""
    path = tmp_path / "huge.txt"
    path.write_text("0 0 0 0 0 0 0 1\n1 1e160 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n")
    with pytest.raises(ReaderError, match="line 2: a position is beyond"):
        read_tum(path)
