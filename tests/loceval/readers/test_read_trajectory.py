"""read_trajectory: dispatch by prefix or content, options, names, bags, and timing."""

from __future__ import annotations

import subprocess
import sys
import types
from enum import StrEnum
from pathlib import Path

import numpy as np
import pytest

from loceval.errors import InputError, ReaderError
from loceval.readers import SourceSpec, TrajectoryFormat, read_trajectory
from loceval.readers import text as text_module
from loceval.trajectory import Trajectory
from tests.factories import (
    MOTIVE_START_NS,
    assert_trajectories_close,
    make_trajectory,
    write_csv,
    write_euroc,
    write_kitti,
    write_motive,
    write_tum,
)

F = TrajectoryFormat
STAMP_ATOL_NS = 500


@pytest.fixture
def truth(rng) -> Trajectory:
    """A 20-pose trajectory with orientations."""
    return make_trajectory(rng, 20)


@pytest.mark.parametrize(
    ("writer", "fmt"),
    [(write_tum, F.TUM), (write_euroc, F.EUROC), (write_csv, F.CSV)],
)
def test_sniffed_dispatch(tmp_path, truth, writer, fmt):
    """Without a prefix the format is sniffed and the source records it."""
    path = writer(tmp_path / "data.bin", truth)
    read = read_trajectory(str(path))
    assert_trajectories_close(read, truth, atol_ns=STAMP_ATOL_NS)
    assert read.source.startswith(f"{fmt.value}:")


def test_kitti_with_relative_times(tmp_path, truth, monkeypatch):
    """A relative times path that only exists beside the poses file is found there."""
    times = tmp_path / "times.txt"
    write_kitti(tmp_path / "00.txt", truth, times_path=times)
    monkeypatch.chdir(tmp_path.parent)
    read = read_trajectory(f"kitti:{tmp_path.name}/00.txt@times=times.txt")
    assert_trajectories_close(read, truth, atol_m=1e-12, atol_ns=STAMP_ATOL_NS, atol_rad=1e-9)


def test_csv_mapping_from_source_text(tmp_path, truth):
    """Column mappings and units in the source text reach the CSV reader."""
    names = {"t": "when", "x": "e", "y": "n", "z": "u"}
    path = write_csv(tmp_path / "a.csv", truth.without_orientation(), names=names, time_unit="ms")
    read = read_trajectory(f"csv:{path}@t=when,x=e,y=n,z=u,time_unit=ms")
    np.testing.assert_array_equal(read.stamps_ns, truth.stamps_ns // 10**6 * 10**6)


def test_motive_selector_and_option(tmp_path, truth):
    """The Motive rigid body and up axis come from the source text."""
    path = write_motive(tmp_path / "take.csv", {"Drone": truth, "Other": truth}, up_axis="z")
    read = read_trajectory(f"{path}@Drone,up=z")
    assert read.child_frame_id == "Drone"
    assert read.name == "Drone"
    expected = truth.shifted(MOTIVE_START_NS - int(truth.stamps_ns[0]))
    assert_trajectories_close(read, expected, atol_m=1e-6, atol_ns=1000, atol_rad=1e-6)


def test_prefix_overrides_content(tmp_path, truth):
    """A prefix forces the reader even when the content says otherwise."""
    path = write_tum(tmp_path / "a.txt", truth)
    with pytest.raises(ReaderError, match=r"a\.txt, line 2: 8 values per line, but every KITTI"):
        read_trajectory(f"kitti:{path}")


def test_default_format_when_no_prefix(tmp_path, truth):
    """The default format is used instead of sniffing."""
    path = write_tum(tmp_path / "a.txt", truth)
    with pytest.raises(ReaderError, match=r"every KITTI line"):
        read_trajectory(str(path), default_format=F.KITTI)
    spec = SourceSpec(None, path)
    assert len(read_trajectory(spec, default_format=F.TUM)) == 20


def test_default_name_is_file_stem(tmp_path, truth):
    """Without a name, the file name without suffix is used; a given name wins."""
    path = write_tum(tmp_path / "slam_run.txt", truth)
    assert read_trajectory(str(path)).name == "slam_run"
    assert read_trajectory(str(path), name="SLAM").name == "SLAM"


@pytest.mark.parametrize(
    ("suffix", "pattern"),
    [
        ("@x=1", r"Unknown option 'x' for the tum source .*; it takes no options"),
        ("@/odom", r"tum sources take no selector, got '/odom' .*; remove the '@' part"),
    ],
)
def test_tum_rejects_selectors_and_options(tmp_path, truth, suffix, pattern):
    """TUM sources take nothing after '@'."""
    path = write_tum(tmp_path / "a.txt", truth)
    with pytest.raises(ReaderError, match=pattern):
        read_trajectory(f"{path}{suffix}")


def test_csv_selector_hint(tmp_path, truth):
    """A CSV source with a bare selector is pointed at the mapping syntax."""
    path = write_csv(tmp_path / "a.csv", truth)
    with pytest.raises(ReaderError, match=r"map columns with @t=COLUMN,x=COLUMN"):
        read_trajectory(f"{path}@time")


def test_kitti_unknown_option(tmp_path, truth):
    """KITTI accepts only a times file."""
    path = write_kitti(tmp_path / "a.txt", truth)
    with pytest.raises(
        ReaderError, match=r"Unknown option 'time' for the kitti source .*; use times"
    ):
        read_trajectory(f"{path}@time=t.txt")


def test_unknown_stamp_source(tmp_path, truth):
    """The stamp source must be header or receive."""
    path = write_tum(tmp_path / "a.txt", truth)
    with pytest.raises(InputError, match=r"Unknown stamp source 'sent'; use 'header' or 'receive'"):
        read_trajectory(str(path), stamp="sent")


def test_missing_file(tmp_path):
    """A missing file is reported as such, with or without a prefix."""
    with pytest.raises(ReaderError, match=r"^No such file: '.*gone\.txt'; check the path\.$"):
        read_trajectory(str(tmp_path / "gone.txt"))
    with pytest.raises(ReaderError, match=r"^No such file: '.*gone\.txt'; check the path\.$"):
        read_trajectory(f"tum:{tmp_path / 'gone.txt'}")


def test_bag_needs_a_selector(tmp_path):
    """A bag without a topic or tf chain asks for one and points at `loceval inspect`."""
    path = tmp_path / "run.bag"
    path.write_bytes(b"#ROSBAG V2.0\n")
    with pytest.raises(
        ReaderError, match=r"is a bag; name a topic or tf chain, e.g. .*run\.bag@/amcl_pose; run "
    ):
        read_trajectory(str(path))


def test_bag_dispatch(tmp_path, truth, monkeypatch):
    """Bags go to read_bag_trajectory with the selector, stamp source and name."""
    calls = []

    class StampSource(StrEnum):
        """Stand-in for the rosbag module's enum."""

        HEADER = "header"
        RECEIVE = "receive"

    def read_bag_trajectory(path, selector, *, stamp, name):
        calls.append((path, selector, stamp, type(stamp), name))
        return truth

    fake = types.ModuleType("loceval.readers.rosbag")
    fake.StampSource = StampSource  # type: ignore[attr-defined]
    fake.read_bag_trajectory = read_bag_trajectory  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "loceval.readers.rosbag", fake)
    path = tmp_path / "run.mcap"
    path.write_bytes(b"\x89MCAP0\r\n")
    assert read_trajectory(f"{path}@tf:map:base_link", stamp="receive") is truth
    assert calls == [
        (path, "tf:map:base_link", StampSource.RECEIVE, StampSource, "tf:map:base_link")
    ]


def test_importing_readers_does_not_import_rosbags():
    """`import loceval.readers` stays free of rosbags until a bag is read."""
    code = "import sys, loceval.readers; print('rosbags' in sys.modules)"
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "False"


@pytest.mark.public_data
@pytest.mark.parametrize(
    ("source", "poses"),
    [
        ("fr2_desk_groundtruth.txt", 20956),
        ("fr2_desk_ORB.txt", 2893),
        ("freiburg1_xyz-groundtruth.txt", 3000),
        ("freiburg1_xyz-rgbdslam.txt", 788),
        ("V102_groundtruth.csv", 16702),
        ("V102.txt", 803),
        ("KITTI_00_gt.txt", 4541),
        ("KITTI_00_ORB.txt", 4541),
        ("KITTI_00_SPTAM.txt", 4541),
        ("kitti:KITTI_00_gt.txt@times=KITTI_00_gt_times.txt", 4541),
        ("motive_take_sample.csv@device02", 40),
        ("motive_take_sample.csv@device03", 40),
        ("motive_take_sample.csv@device05", 39),
        ("ROS_example.bag@groundtruth", 12765),
    ],
)
def test_public_sources(public_data: Path, monkeypatch, source, poses):
    """Every public recording reads through read_trajectory with its known pose count."""
    monkeypatch.chdir(public_data)
    assert len(read_trajectory(source)) == poses


def test_large_tum_file_uses_the_c_parser(tmp_path, rng, monkeypatch):
    """200,000 TUM lines with a comment header are parsed without the line-by-line pass."""
    lines = 200_000
    t = 1_311_868_163.8697 + np.arange(lines) * 0.01
    quat = rng.normal(size=(lines, 4))
    quat /= np.linalg.norm(quat, axis=1)[:, None]
    table = np.column_stack([t, rng.normal(size=(lines, 3)), quat])
    path = tmp_path / "big.txt"
    with path.open("w") as fh:
        fh.write("# ground truth trajectory\n# timestamp tx ty tz qx qy qz qw\n")
        np.savetxt(fh, table, fmt=["%.6f"] + ["%.9f"] * 7)

    def no_slow_pass(*_args: object, **_kwargs: object) -> None:
        raise AssertionError

    monkeypatch.setattr(text_module, "_parse_slow", no_slow_pass)
    read = read_trajectory(f"tum:{path}")
    assert len(read) == lines
    np.testing.assert_allclose(read.positions_xyz[-1], table[-1, 1:4])


def test_repeated_stamps_kept_only_as_evo_keeps_them(tmp_path: Path) -> None:
    """A repeated stamp: dropped by default; kept 1 ns apart inside keeping_duplicate_stamps."""
    from loceval.readers import keeping_duplicate_stamps, read_tum

    rows = [(0.0, 0.0), (0.1, 1.0), (0.1, 2.0), (0.1, 3.0), (0.2, 4.0), (0.3, 5.0)]
    path = tmp_path / "rep.txt"
    path.write_text("".join(f"{t} {x} 0 0 0 0 0 1\n" for t, x in rows))
    dropped = read_tum(path)
    assert dropped.positions_xyz[:, 0].tolist() == [0.0, 1.0, 4.0, 5.0]
    assert any("2 poses with a duplicate stamp dropped" in w for w in dropped.warnings)
    with keeping_duplicate_stamps():
        kept = read_tum(path)
    assert kept.positions_xyz[:, 0].tolist() == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
    assert (kept.stamps_ns - dropped.stamps_ns[0]).tolist() == [
        0, 100_000_000, 100_000_001, 100_000_002, 200_000_000, 300_000_000,
    ]  # fmt: skip
    said = "2 poses repeat the stamp of the pose before; kept as evo"
    assert any(said in w for w in kept.warnings)
    assert len(read_tum(path)) == 4  # the setting ends with its block
