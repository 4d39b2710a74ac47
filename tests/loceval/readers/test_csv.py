"""Generic CSV reader: header names, mappings, units, delimiters and errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from loceval.errors import ReaderError
from loceval.readers import read_csv
from tests.factories import assert_trajectories_close, make_trajectory, write_csv

STAMP_ATOL_NS = 500


def test_plain_names_round_trip(tmp_path, rng):
    """``t,x,y,z,qx,qy,qz,qw`` reads back what was written."""
    truth = make_trajectory(rng, 40)
    read = read_csv(write_csv(tmp_path / "a.csv", truth), name="est")
    assert_trajectories_close(read, truth, atol_ns=STAMP_ATOL_NS)
    assert read.name == "est"
    assert read.source == f"csv:{tmp_path / 'a.csv'}"


@pytest.mark.parametrize("delimiter", [",", ";", "\t", " "])
def test_delimiters_are_sniffed(tmp_path, rng, delimiter):
    """Comma, semicolon, tab and whitespace-separated files are read alike."""
    truth = make_trajectory(rng, 10)
    read = read_csv(write_csv(tmp_path / "a.csv", truth, delimiter=delimiter))
    assert_trajectories_close(read, truth, atol_ns=STAMP_ATOL_NS)


def test_recognised_names_with_units_in_brackets(tmp_path, rng):
    """Names like ``Time (s)``, ``pos_x [m]`` and ``q_w`` are recognised in any order."""
    truth = make_trajectory(rng, 10)
    names = {
        "qw": "q_w",
        "t": "Time (s)",
        "x": "pos_x [m]",
        "y": "pos_y [m]",
        "z": "pos_z [m]",
        "qx": "q_x",
        "qy": "q_y",
        "qz": "q_z",
    }
    read = read_csv(write_csv(tmp_path / "a.csv", truth, names=names))
    assert_trajectories_close(read, truth, atol_ns=STAMP_ATOL_NS)


def test_millimetres_from_the_header(tmp_path, rng):
    """A ``[mm]`` unit on the position columns is converted to metres."""
    truth = make_trajectory(rng, 10, orientation=False)
    names = {"t": "t", "x": "x [mm]", "y": "y [mm]", "z": "z [mm]"}
    read = read_csv(write_csv(tmp_path / "a.csv", truth, names=names, length_scale=0.001))
    assert_trajectories_close(read, truth, atol_m=1e-12, atol_ns=STAMP_ATOL_NS)


def test_length_unit_option(tmp_path, rng):
    """``length_unit="cm"`` scales plain position columns."""
    truth = make_trajectory(rng, 10, orientation=False)
    read = read_csv(write_csv(tmp_path / "a.csv", truth, length_scale=0.01), length_unit="cm")
    assert_trajectories_close(read, truth, atol_m=1e-12, atol_ns=STAMP_ATOL_NS)
    assert read.source.endswith("@length_unit=cm")


@pytest.mark.parametrize(("suffix", "unit"), [("ns", "ns"), ("us", "us"), ("ms", "ms")])
def test_integer_time_units_from_name_are_exact(tmp_path, rng, suffix, unit):
    """``time_ns``/``time_us``/``time_ms`` integer stamps become exact nanoseconds."""
    truth = make_trajectory(rng, 10, dt_ns=10_000_000)
    names = {"t": f"time_{suffix}", "x": "x", "y": "y", "z": "z"}
    read = read_csv(write_csv(tmp_path / "a.csv", truth, names=names, time_unit=unit))
    np.testing.assert_array_equal(read.stamps_ns, truth.stamps_ns)


def test_time_unit_option_overrides_name(tmp_path, rng):
    """An explicit time unit wins over the column name."""
    truth = make_trajectory(rng, 10, orientation=False)
    names = {"t": "stamp", "x": "x", "y": "y", "z": "z"}
    path = write_csv(tmp_path / "a.csv", truth, names=names, time_unit="ns")
    read = read_csv(path, time_unit="ns")
    np.testing.assert_array_equal(read.stamps_ns, truth.stamps_ns)


def test_rostopic_echo_csv(tmp_path):
    """``rostopic echo -p`` columns: header stamp (ns) wins over %time, pose fields found."""
    header = (
        "%time,field.header.seq,field.header.stamp,field.header.frame_id,"
        "field.pose.position.x,field.pose.position.y,field.pose.position.z,"
        "field.pose.orientation.x,field.pose.orientation.y,field.pose.orientation.z,"
        "field.pose.orientation.w"
    )
    rows = [f"{9000 + i},{i},{1000 + i},map,{i}.0,0,0,0,0,0,1" for i in range(3)]
    path = tmp_path / "pose.csv"
    path.write_text("\n".join([header, *rows]) + "\n")
    read = read_csv(path)
    assert read.stamps_ns.tolist() == [1000, 1001, 1002]
    assert read.quat_xyzw is not None


def test_explicit_mapping(tmp_path, rng):
    """A mapping names columns the defaults would not find."""
    truth = make_trajectory(rng, 10, orientation=False)
    names = {"t": "when", "x": "east", "y": "north", "z": "up"}
    path = write_csv(tmp_path / "a.csv", truth, names=names)
    read = read_csv(path, columns={"t": "when", "x": "east", "y": "NORTH", "z": "up"})
    assert_trajectories_close(read, truth, atol_ns=STAMP_ATOL_NS)
    assert "t=when" in read.source


def test_position_only_planar(tmp_path, rng):
    """``t, x, y`` columns give z = 0 and no orientations."""
    truth = make_trajectory(rng, 10, orientation=False, planar=True)
    read = read_csv(write_csv(tmp_path / "a.csv", truth, names={"t": "t", "x": "x", "y": "y"}))
    assert read.quat_xyzw is None
    assert_trajectories_close(read, truth, atol_ns=STAMP_ATOL_NS)


def test_hash_prefixed_header_and_comment_lines_above(tmp_path):
    """A ``#t,x,y`` header is used and free text above it is ignored."""
    path = tmp_path / "a.csv"
    path.write_text("exported by tool 1.2\n#t,x,y\n1,0,0\n2,1,0\n3,2,0\n")
    assert read_csv(path).stamps_ns.tolist() == [10**9, 2 * 10**9, 3 * 10**9]


def test_quoted_cells_and_extra_text_columns(tmp_path):
    """Quoted numbers and unused text columns are fine."""
    path = tmp_path / "a.csv"
    path.write_text('t,label,x,y\n1,"a, b",0,0\n"2",c,1,0\n3,d,"2",0\n')
    read = read_csv(path)
    np.testing.assert_array_equal(read.positions_xyz[:, 0], [0.0, 1.0, 2.0])


def test_empty_cells_drop_rows_with_warning(tmp_path):
    """Rows with an empty used cell are dropped and counted."""
    path = tmp_path / "a.csv"
    path.write_text("t,x,y,note\n1,0,0,\n2,,0,a\n3,2,0,\n4,3,0,\n")
    read = read_csv(path)
    assert read.stamps_ns.tolist() == [10**9, 3 * 10**9, 4 * 10**9]
    assert any("1 of 4 rows dropped" in w and "line 3" in w for w in read.warnings)


@pytest.mark.parametrize(
    ("content", "kwargs", "pattern"),
    [
        ("a,b,c\n1,2,3\n", {}, r"a\.csv, line 1: no column for 't' among \['a', 'b', 'c'\]"),
        ("t,x,z\n1,2,3\n", {}, r"line 1: no column for 'y' among .*csv:.*a\.csv@y=COLUMN"),
        ("t,x,y\n1,2,3\n", {"columns": {"t": "time"}}, r"line 1: no column 'time' for 't'"),
        ("t,x,y\n1,2,3\n", {"columns": {"yaw": "t"}}, r"unknown column key 'yaw'"),
        (
            "t,x,y,qx,qy,qz\n1,2,3,0,0,0\n",
            {},
            r"quaternion columns \['qx', 'qy', 'qz'\] found but not \['qw'\]",
        ),
        ("1,2,3\n4,5,6\n", {}, r"a\.csv, line 1: numbers but no header row"),
        ("t,x,y\n", {}, r"a\.csv: no rows of numbers under a header"),
        ("t,x,y\n1,2,3\n2,x2,3\n", {}, r"line 3: 'x2' in column 'x' is not a number"),
        ("t,x,y\n1,2,3\n2,nan,3\n3,1,1\n", {}, r"line 3: position is NaN or inf"),
        ("t,x,y\n1,2,3\n2,3\n", {}, r"line 3: 2 cells, but column 'y' is cell 3"),
        ("t,x,y\n1,2,3\n", {"time_unit": "h"}, r"unknown time unit 'h'"),
        ("t [h],x,y\n1,2,3\n", {}, r"unknown time unit 'h' in column 't \[h\]'"),
        ("t,x [ft],y\n1,2,3\n", {}, r"unknown length unit 'ft' for column 'x \[ft\]'"),
        (
            "t,x,y\n1400000000000000000,0,0\n",
            {},
            r"stamps up to 1\.4e\+18 are too large for seconds; .*@time_unit=ns",
        ),
        ("t,x,y\n1,2,3\n2,2,3\n", {}, r"a\.csv: 2 poses, but at least 3"),
        (
            "t_ms,x,y\n1,0,0\n9223372036854775,0,0\n",
            {},
            r"line 3: stamp 9223372036854775 is too large for its unit",
        ),
        ("t,x,y\nnan,0,0\nnan,1,1\nnan,2,2\n", {}, r"line 2: stamp nan s is not a usable"),
    ],
)
def test_errors_name_file_line_and_fix(tmp_path, content, kwargs, pattern):
    """Each bad CSV gets a ReaderError naming the file, line or column, and the fix."""
    path = tmp_path / "a.csv"
    path.write_text(content)
    with pytest.raises(ReaderError, match=pattern):
        read_csv(path, **kwargs)


def test_missing_file(tmp_path):
    """A missing CSV names the path."""
    with pytest.raises(ReaderError, match=r"No such file: '.*x\.csv'; check the path\."):
        read_csv(tmp_path / "x.csv")


@given(
    stamps_us=st.lists(st.integers(0, 4 * 10**15), min_size=3, max_size=25, unique=True),
    data=st.data(),
    delimiter=st.sampled_from([",", ";", "\t"]),
    unit=st.sampled_from(["s", "ns"]),
)
def test_round_trip_property(tmp_path_factory, stamps_us, data, delimiter, unit):
    """Any microsecond stamps and finite positions survive write -> read, any delimiter."""
    stamps = [s * 1000 + (7 if unit == "ns" else 0) for s in stamps_us]
    n = len(stamps)
    floats = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
    positions = np.array(data.draw(st.lists(floats, min_size=3 * n, max_size=3 * n)))
    base = make_trajectory(np.random.default_rng(0), n, orientation=False)
    truth = type(base)(np.sort(np.array(stamps, dtype=np.int64)), positions.reshape(n, 3))
    names = {"t": f"time_{unit}", "x": "x", "y": "y", "z": "z"}
    path = tmp_path_factory.mktemp("csv") / "a.csv"
    write_csv(path, truth, names=names, delimiter=delimiter, time_unit=unit)
    read = read_csv(path)
    assert_trajectories_close(read, truth, atol_m=0.0, atol_ns=1000 if unit == "s" else 0)
