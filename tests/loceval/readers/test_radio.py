"""Anchors and ranges CSV readers: round trips, dropped rows per reason, clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from loceval.errors import InputError, ReaderError
from loceval.readers.radio import Anchors, Ranges, read_anchors, read_ranges
from tests.radio_factory import (
    ANCHOR_IDS,
    ANCHOR_XYZ,
    T0_NS,
    make_anchors,
    make_ranges,
    write_anchors_csv,
    write_ranges_csv,
)

ANCHORS_CSV = "id,x,y,z\nA1,0,0,2.5\nA2,10,0,2.5\nA3,0,8,2.4\n"


def test_round_trip(tmp_path, rng):
    """Written anchors and ranges read back exactly (nanosecond stamps, shortest floats)."""
    rec = make_ranges(rng, end_s=10.0)
    anchors = read_anchors(write_anchors_csv(tmp_path / "anchors.csv", make_anchors()))
    assert anchors.ids == ANCHOR_IDS
    np.testing.assert_array_equal(anchors.positions_xyz, ANCHOR_XYZ)
    ranges = read_ranges(write_ranges_csv(tmp_path / "ranges.csv", rec.ranges), anchors)
    np.testing.assert_array_equal(ranges.stamps_ns, rec.ranges.stamps_ns)
    np.testing.assert_array_equal(ranges.anchor_index, rec.ranges.anchor_index)
    np.testing.assert_array_equal(ranges.range_m, rec.ranges.range_m)
    assert ranges.rssi is None
    assert ranges.warnings == ()
    assert ranges.source == str(tmp_path / "ranges.csv")


def test_rssi_is_read_when_present(tmp_path, rng):
    """The optional rssi column is read alongside the ranges."""
    rec = make_ranges(rng, end_s=2.0)
    path = write_ranges_csv(tmp_path / "ranges.csv", rec.ranges, rssi=True)
    ranges = read_ranges(path, make_anchors())
    assert ranges.rssi is not None
    np.testing.assert_allclose(ranges.rssi, np.round(-60.0 - rec.ranges.range_m, 1))


def test_bad_rows_are_dropped_and_counted_per_reason(tmp_path):
    """NaN, negative, unknown-anchor, bad-time and short rows are dropped and named."""
    path = tmp_path / "ranges.csv"
    path.write_text(
        "t,anchor_id,range_m\n"
        "0.0,A1,3.0\n"
        "0.1,A2,nan\n"  # line 3: NaN range
        "0.2,A3,-1.5\n"  # negative
        "0.3,Z9,4.0\n"  # unknown anchor
        "0.4,Q7,4.0\n"  # unknown anchor
        "abc,A1,4.0\n"  # time not a number
        "0.5,A1\n"  # short row
        "0.6,A2,\n"  # empty range
        "0.7,A3,5.0\n",
        encoding="utf-8",
    )
    ranges = read_ranges(path, read_anchors(_anchors(tmp_path)))
    assert len(ranges) == 2
    assert ranges.range_m.tolist() == [3.0, 5.0]
    (note,) = ranges.warnings
    assert note == (
        f"{path}: 7 of 9 range rows dropped (first at line 3): 1 with other than 3 cells; "
        "1 whose time is not a finite number; 2 whose range is NaN or not a number; "
        "1 with a negative range; 2 with an anchor id not in the anchors file ('Q7', 'Z9')."
    )


def test_no_usable_row_is_an_error(tmp_path):
    """A ranges file whose rows all refer to unknown anchors is refused."""
    with pytest.raises(ReaderError, match="none of the 2 range rows is usable"):
        _read_ranges_text(tmp_path, "t,anchor_id,range_m\n0,X,1\n1,Y,2\n")


def test_header_only_is_an_error(tmp_path):
    """A ranges file with a header and no rows is refused."""
    with pytest.raises(ReaderError, match="a header but no range rows"):
        _read_ranges_text(tmp_path, "t,anchor_id,range_m\n\n")


def test_unsorted_ranges_are_sorted(tmp_path):
    """Rows out of time order come back sorted (stable within a stamp)."""
    ranges = _read_ranges_text(tmp_path, "t,anchor_id,range_m\n2,A1,1\n1,A2,2\n1,A3,3\n")
    assert ranges.stamps_ns.tolist() == [10**9, 10**9, 2 * 10**9]
    assert ranges.anchor_index.tolist() == [1, 2, 0]


def test_other_spellings_delimiters_and_time_units(tmp_path):
    """A '#' header, whitespace cells, column aliases and a t_ns column are understood."""
    path = tmp_path / "ranges.txt"
    path.write_text(
        "# anchor survey of the tag\n# t_ns anchor distance\n1700000000000000001 A2 4.5\n",
        encoding="utf-8",
    )
    ranges = read_ranges(path, read_anchors(_anchors(tmp_path)))
    assert ranges.stamps_ns.tolist() == [T0_NS + 1]
    assert ranges.anchor_index.tolist() == [1]
    semi = tmp_path / "anchors.csv"
    semi.write_text("Anchor;X [m];Y [m];Z [m]\n1;0;0;2\n2;5;0;2\n3;0;5;2\n", encoding="utf-8")
    assert read_anchors(semi).ids == ("1", "2", "3")


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("id,x,y,z\nA1,0,0,2\nA2,1,0,2\nA1,0,1,2\n", "anchor id 'A1' already used on line 2"),
        ("id,x,y,z\nA1,0,0,2\nA2,nan,0,2\nA3,0,1,2\n", "x of anchor 'A2' is 'nan'"),
        ("id,x,y,z\nA1,0,0,2\nA2,1,0,2\n", "2 anchors, but positioning needs at least 3"),
        ("id,x,y\nA1,0,0\nA2,1,0\nA3,0,1\n", "no column for 'z'"),
        ("A1,0,0,2\nA2,1,0,2\nA3,0,1,2\n", "numbers but no header row"),
        ("id,x,y,z\nA1,0,0,2\nA2,1,0\nA3,0,1,2\n", "line 3: 3 cells but the header has 4"),
        ("id,x,y,z\nA1,0,0,2\n,1,0,2\nA3,0,1,2\n", "line 3: the anchor id is empty"),
        ("\n\n", "the anchors file is empty"),
    ],
)
def test_bad_anchor_files_are_clear_errors(tmp_path, text, match):
    """Duplicate ids, NaN, too few anchors, missing columns: a ReaderError naming the line."""
    path = tmp_path / "anchors.csv"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ReaderError, match=match):
        read_anchors(path)


def test_missing_file_is_a_reader_error(tmp_path):
    """A path that does not exist is a ReaderError, not an OSError."""
    with pytest.raises(ReaderError, match="No such file"):
        read_anchors(tmp_path / "nope.csv")


def test_ranges_missing_a_column(tmp_path):
    """A ranges header without a range column names what is missing."""
    with pytest.raises(ReaderError, match="no column for 'range_m'"):
        _read_ranges_text(tmp_path, "t,anchor_id,rssi\n0,A1,-70\n")


def test_unknown_time_unit(tmp_path):
    """A time column in an unknown unit is refused with the units that work."""
    with pytest.raises(ReaderError, match="unknown time unit 'h'"):
        _read_ranges_text(tmp_path, "time [h],anchor_id,range_m\n0,A1,1\n")


def test_value_types_check_their_arrays():
    """Anchors and Ranges refuse inconsistent arrays with an InputError."""
    with pytest.raises(InputError, match="Anchor id 'a' appears twice"):
        Anchors(("a", "b", "a"), np.zeros((3, 3)))
    with pytest.raises(InputError, match=r"must have shape \(3, 3\)"):
        Anchors(("a", "b", "c"), np.zeros((3, 2)))
    with pytest.raises(InputError, match="at least 3"):
        Anchors(("a", "b"), np.zeros((2, 3)))
    anchors = Anchors(("a", "b", "c"), np.eye(3))
    with pytest.raises(InputError, match="finite and non-negative"):
        Ranges(anchors, np.array([0, 1]), np.array([0, 1]), np.array([1.0, -1.0]))
    with pytest.raises(InputError, match="sorted by time"):
        Ranges(anchors, np.array([1, 0]), np.array([0, 1]), np.array([1.0, 1.0]))
    with pytest.raises(InputError, match=r"lie in 0\.\.2"):
        Ranges(anchors, np.array([0, 1]), np.array([0, 3]), np.array([1.0, 1.0]))
    ranges = Ranges(anchors, [0, 1], [0, 1], [1.0, 2.0])
    assert not ranges.range_m.flags.writeable


def _anchors(tmp_path):
    path = tmp_path / "anchors.csv"
    path.write_text(ANCHORS_CSV, encoding="utf-8")
    return path


def _read_ranges_text(tmp_path, text):
    """Write ``text`` as ranges.csv and read it against the three anchors of ANCHORS_CSV."""
    path = tmp_path / "ranges.csv"
    path.write_text(text, encoding="utf-8")
    return read_ranges(path, read_anchors(_anchors(tmp_path)))
