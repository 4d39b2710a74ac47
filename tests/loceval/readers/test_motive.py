"""OptiTrack Motive CSV reader: labels, bodies, units, axes, time and tracking loss."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from loceval.errors import ReaderError
from loceval.readers import read_motive
from loceval.readers.motive import MOTIVE_FRAME_ID, Y_UP_TO_Z_UP
from tests.factories import (
    MOTIVE_START_NS,
    assert_trajectories_close,
    make_trajectory,
    write_motive,
)

# Motive writes 9 significant digits here; times are relative seconds of a short take.
ATOL_M = 1e-6
ATOL_RAD = 1e-6
ATOL_NS = 1000


@pytest.fixture
def bodies(rng):
    """Two rigid bodies sharing 30 frames at 100 Hz."""
    first = make_trajectory(rng, 30, t0_ns=MOTIVE_START_NS)
    second = make_trajectory(rng, 30, t0_ns=MOTIVE_START_NS)
    return {"Drone": first, "Helmet 2": second}


def test_round_trip_converts_y_up_to_z_up(tmp_path, bodies):
    """A Y-up export reads back as the REP 103 poses it was written from."""
    path = write_motive(tmp_path / "take.csv", bodies)
    read = read_motive(path, rigid_body="Drone")
    assert_trajectories_close(
        read, bodies["Drone"], atol_m=ATOL_M, atol_ns=ATOL_NS, atol_rad=ATOL_RAD
    )
    assert read.frame_id == MOTIVE_FRAME_ID
    assert read.child_frame_id == "Drone"
    assert read.source == f"motive:{path}@Drone"
    assert any("(x, y, z) -> (x, -z, y)" in w for w in read.warnings)


def test_conversion_is_a_proper_rotation_sending_y_to_z():
    """The axis change is a rotation (det +1) that maps Motive's +Y to +Z and keeps +X."""
    matrix = Y_UP_TO_Z_UP.rotation
    assert np.isclose(np.linalg.det(matrix), 1.0)
    np.testing.assert_array_equal(matrix @ [0, 1, 0], [0, 0, 1])
    np.testing.assert_array_equal(matrix @ [1, 0, 0], [1, 0, 0])


def test_orientation_is_left_multiplied(tmp_path, bodies):
    """A body aligned with Motive's axes reads as the +90° x rotation (world change only)."""
    identity = bodies["Drone"]
    path = tmp_path / "take.csv"
    write_motive(path, {"Drone": identity}, up_axis="z")  # written without conversion
    read = read_motive(path, up_axis="y")
    assert read.quat_xyzw is not None
    assert identity.quat_xyzw is not None
    expected = Rotation.from_matrix(Y_UP_TO_Z_UP.rotation) * Rotation.from_quat(identity.quat_xyzw)
    delta = Rotation.from_quat(read.quat_xyzw).inv() * expected
    np.testing.assert_allclose(delta.magnitude(), 0.0, atol=ATOL_RAD)


def test_second_body_with_space_in_name(tmp_path, bodies):
    """Bodies are picked by name, spaces included."""
    path = write_motive(tmp_path / "take.csv", bodies)
    read = read_motive(path, rigid_body="Helmet 2")
    assert_trajectories_close(
        read, bodies["Helmet 2"], atol_m=ATOL_M, atol_ns=ATOL_NS, atol_rad=ATOL_RAD
    )


def test_single_body_needs_no_name(tmp_path, bodies):
    """With one rigid body in the export, no name is needed."""
    path = write_motive(tmp_path / "take.csv", {"Drone": bodies["Drone"]})
    assert read_motive(path).child_frame_id == "Drone"


def test_several_bodies_need_a_name(tmp_path, bodies):
    """With several bodies, the error lists them and the selector syntax."""
    path = write_motive(tmp_path / "take.csv", bodies)
    with pytest.raises(
        ReaderError, match=r"holds 2 rigid bodies \('Drone', 'Helmet 2'\); pick one with motive:"
    ):
        read_motive(path)


def test_unknown_body(tmp_path, bodies):
    """An unknown name is refused with the names there are."""
    path = write_motive(tmp_path / "take.csv", bodies)
    with pytest.raises(ReaderError, match=r"no rigid body 'Drone:Marker1'; the export holds"):
        read_motive(path, rigid_body="Drone:Marker1")


def test_lost_frames_are_dropped_and_counted(tmp_path, bodies):
    """Frames with empty cells are dropped and the warning counts them."""
    path = write_motive(tmp_path / "take.csv", bodies, lost={"Drone": [3, 4, 5, 20]})
    read = read_motive(path, rigid_body="Drone")
    assert len(read) == 26
    assert any("4 of 30 frames dropped: rigid body 'Drone' not tracked" in w for w in read.warnings)
    other = read_motive(path, rigid_body="Helmet 2")
    assert len(other) == 30


@pytest.mark.parametrize("units", ["Millimeters", "Centimeters"])
def test_length_units(tmp_path, bodies, units):
    """Millimetre and centimetre exports become metres."""
    path = write_motive(tmp_path / "take.csv", bodies, length_units=units)
    read = read_motive(path, rigid_body="Drone")
    assert_trajectories_close(
        read, bodies["Drone"], atol_m=ATOL_M * 10, atol_ns=ATOL_NS, atol_rad=ATOL_RAD
    )


def test_unknown_length_unit(tmp_path, bodies):
    """Inches are refused with the units that work."""
    path = write_motive(tmp_path / "take.csv", bodies, length_units="Inches")
    with pytest.raises(ReaderError, match=r"Length Units 'Inches' is not Meters, Centimeters"):
        read_motive(path, rigid_body="Drone")


def test_missing_length_unit_assumes_metres(tmp_path, bodies):
    """Without Length Units the positions are metres and a warning says so."""
    path = write_motive(tmp_path / "take.csv", bodies)
    path.write_text(path.read_text().replace("Length Units,Meters,", ""))
    read = read_motive(path, rigid_body="Drone")
    assert any("no Length Units" in w for w in read.warnings)
    # write_motive writes metres: read as metres, the positions are the bodies' own.
    assert_trajectories_close(
        read, bodies["Drone"], atol_m=ATOL_M, atol_ns=ATOL_NS, atol_rad=ATOL_RAD
    )


def test_euler_export_is_refused(tmp_path, bodies):
    """Euler-angle exports ask for a Quaternion re-export."""
    path = write_motive(tmp_path / "take.csv", bodies, rotation_type="XYZ")
    with pytest.raises(ReaderError, match=r"re-export the take with Rotation Type Quaternion"):
        read_motive(path, rigid_body="Drone")


def test_z_up_option(tmp_path, bodies):
    """``up_axis="z"`` reads a Z-up export without rotating it."""
    path = write_motive(tmp_path / "take.csv", bodies, up_axis="z")
    read = read_motive(path, rigid_body="Drone", up_axis="z")
    assert_trajectories_close(
        read, bodies["Drone"], atol_m=ATOL_M, atol_ns=ATOL_NS, atol_rad=ATOL_RAD
    )
    assert any("already Z-up" in w for w in read.warnings)
    assert read.source.endswith("@Drone,up=z")


def test_up_axis_header_key(tmp_path, bodies):
    """An ``Up Axis,Z`` header key is honoured."""
    path = write_motive(tmp_path / "take.csv", bodies, up_axis="z", extra_meta={"Up Axis": "Z"})
    read = read_motive(path, rigid_body="Drone")
    assert_trajectories_close(
        read, bodies["Drone"], atol_m=ATOL_M, atol_ns=ATOL_NS, atol_rad=ATOL_RAD
    )


def test_bad_up_axis(tmp_path, bodies):
    """Only Y and Z are up axes."""
    path = write_motive(tmp_path / "take.csv", bodies)
    with pytest.raises(ReaderError, match=r"up axis 'x' is not Y or Z; give up=y or up=z"):
        read_motive(path, rigid_body="Drone", up_axis="x")


def test_capture_start_time_read_as_utc(tmp_path, bodies):
    """Stamps are Capture Start Time (as UTC) plus Time (Seconds), with a warning."""
    path = write_motive(tmp_path / "take.csv", bodies)
    read = read_motive(path, rigid_body="Drone")
    assert int(read.stamps_ns[0]) == MOTIVE_START_NS
    assert any("read as UTC" in w for w in read.warnings)


def test_unreadable_start_time_gives_relative_stamps(tmp_path, bodies):
    """Without a readable start time, stamps count from the start of the take."""
    path = write_motive(tmp_path / "take.csv", bodies, capture_start="sometime")
    read = read_motive(path, rigid_body="Drone")
    assert int(read.stamps_ns[0]) == 0
    assert any("seconds since the start of the take" in w for w in read.warnings)


def test_position_only_body(tmp_path, bodies):
    """A body exported without rotation columns is position-only."""
    path = write_motive(tmp_path / "take.csv", {"Drone": bodies["Drone"]}, rotations=False)
    read = read_motive(path)
    assert read.quat_xyzw is None
    assert len(read) == 30


def test_not_a_motive_file(tmp_path):
    """A CSV without the Format Version line is refused."""
    path = tmp_path / "a.csv"
    path.write_text("t,x,y\n1,2,3\n")
    with pytest.raises(ReaderError, match=r"a\.csv, line 1: no 'Format Version' header"):
        read_motive(path)


def test_no_frame_row(tmp_path):
    """An export cut before the Frame row is refused."""
    path = tmp_path / "a.csv"
    path.write_text("Format Version,1.23\n\n,Type,Rigid Body\n")
    with pytest.raises(ReaderError, match=r"no 'Frame,Time \(Seconds\),\.\.\.' row"):
        read_motive(path)


def test_bad_cell_is_named(tmp_path, bodies):
    """A non-number names the line and the rigid body column."""
    path = write_motive(tmp_path / "take.csv", {"Drone": bodies["Drone"]})
    lines = path.read_text().splitlines()
    cells = lines[9].split(",")
    cells[6] = "oops"
    lines[9] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(
        ReaderError, match=r"take\.csv, line 10: 'oops' in column 'Drone Position X'"
    ):
        read_motive(path)


@pytest.mark.public_data
class TestPublicSample:
    @pytest.mark.parametrize(
        ("body", "poses"), [("device02", 40), ("device03", 40), ("device05", 39)]
    )
    def test_pose_counts(self, public_data: Path, body, poses):
        """The pathviewr sample holds 40 frames; device05 loses one."""
        read = read_motive(public_data / "motive_take_sample.csv", rigid_body=body)
        assert len(read) == poses
        assert read.has_orientation
        dropped = [w for w in read.warnings if "frames dropped" in w]
        assert len(dropped) == (40 - poses)

    def test_first_pose_in_rep103(self, public_data: Path):
        """device02's first position (0.142319, 0.160392, 2.000101) Y-up becomes (x, -z, y)."""
        read = read_motive(public_data / "motive_take_sample.csv", rigid_body="device02")
        np.testing.assert_allclose(read.positions_xyz[0], [0.142319, -2.000101, 0.160392])
        # Capture Start Time 2019-09-18 04.30.02.695 PM (UTC) + 722.1 s
        assert int(read.stamps_ns[0]) == 1_568_824_202_695_000_000 + 722_100_000_000

    def test_several_bodies_listed(self, public_data: Path):
        """Without a name the three bodies are listed."""
        with pytest.raises(
            ReaderError, match=r"3 rigid bodies \('device02', 'device03', 'device05'\)"
        ):
            read_motive(public_data / "motive_take_sample.csv")
