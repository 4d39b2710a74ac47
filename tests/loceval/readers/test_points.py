"""Control-point surveys and visits tables: columns, sigmas and every bad-input message."""

from __future__ import annotations

import numpy as np
import pytest

from loceval.errors import ReaderError
from loceval.readers.points import (
    looks_like_control_points,
    looks_like_visits,
    read_control_points,
    read_visits,
)

_SURVEY_HV = """ID; X [m]; Y [m]; Z [m]; sigma_xy_m; sigma_z_m
A;0;0;0;0.001;0.003
B;1;0;0;0.001;0.003
C;0;1;0;0.001;0.003
"""


def _write(tmp_path, text: str, name: str = "survey.csv"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_reads_points_with_one_sigma(tmp_path):
    """id,x,y,z,sigma_m: positions in metres and the same sigma on every axis."""
    pts = read_control_points(
        _write(
            tmp_path,
            "# survey 2026-11\nid,x,y,z,sigma_m\nA,1,2,3,0.001\nB,4,5,6,0.002\nC,7,8,9.5,0\n",
        )
    )
    assert pts.ids == ("A", "B", "C")
    np.testing.assert_array_equal(pts.positions_xyz[2], [7, 8, 9.5])
    np.testing.assert_array_equal(pts.sigma_xyz[1], [0.002] * 3)
    assert pts.source == "points:survey.csv"


def test_reads_horizontal_and_vertical_sigma_with_units_and_semicolons(tmp_path):
    """sigma_xy_m / sigma_z_m and headers with units in brackets, ; separated."""
    pts = read_control_points(
        _write(
            tmp_path,
            _SURVEY_HV,
        )
    )
    np.testing.assert_array_equal(pts.sigma_xyz[0], [0.001, 0.001, 0.003])


def test_sniffs_points_and_visits_headers():
    """A survey header has id,x,y,z and no time; a visits header has id,t_start,t_end."""
    assert looks_like_control_points("id,x,y,z,sigma_m")
    assert not looks_like_control_points("t,x,y,z")
    assert not looks_like_control_points("#timestamp x y z qx qy qz qw")
    assert looks_like_visits("id,t_start,t_end")
    assert not looks_like_visits("id,x,y,z")


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("id,x,y,z\nA,0,0,0\nA,1,0,0\nB,0,1,0\n", "'A' appears more than once"),
        ("id,x,y,z\nA,0,0,0\nB,1,0,0\n", "at least 3"),
        ("id,x,y\nA,0,0\n", "no column 'z'"),
        ("id,x,y,z\nA,0,0,zero\nB,1,0,0\nC,0,1,0\n", "line 2: z 'zero' is not a number"),
        ("id,x,y,z\nA,0,nan,0\nB,1,0,0\nC,0,1,0\n", "finite"),
        ("id,x,y,z,sigma_m\nA,0,0,0,-1\nB,1,0,0,0\nC,0,1,0,0\n", "sigma is negative"),
        ("id,x,y,z,sigma_xy_m\nA,0,0,0,1\nB,1,0,0,0\nC,0,1,0,0\n", "both sigma_xy_m and sigma_z_m"),
        ("id,x,y,z\n,0,0,0\nB,1,0,0\nC,0,1,0\n", "no id"),
        ("id,x,y,z\n", "no rows"),
        ("", "empty"),
        ("id,x,y,z\nA,0,0\n", "3 cells, the header needs 4"),
    ],
)
def test_bad_surveys_are_named(tmp_path, text, match):
    """Each bad survey gets a message that names the problem and the file."""
    with pytest.raises(ReaderError, match=match) as info:
        read_control_points(_write(tmp_path, text))
    assert "survey.csv" in str(info.value)


def test_visits_name_unknown_points_and_backward_windows(tmp_path):
    """A visit of a point that is not surveyed, or one that ends first, is refused."""
    pts = read_control_points(_write(tmp_path, "id,x,y,z\nA,0,0,0\nB,1,0,0\nC,0,1,0\n"))
    ok = read_visits(_write(tmp_path, "id,t_start,t_end\nB,12.5,15\nA,10,12\n", "v.csv"), pts)
    assert ok.point_index.tolist() == [0, 1]  # sorted by start
    assert ok.start_ns.tolist() == [10_000_000_000, 12_500_000_000]
    with pytest.raises(ReaderError, match="not in the survey: 'Z'"):
        read_visits(_write(tmp_path, "id,t_start,t_end\nZ,1,2\n", "v.csv"), pts)
    with pytest.raises(ReaderError, match="line 2: the visit ends before it starts"):
        read_visits(_write(tmp_path, "id,t_start,t_end\nA,5,2\n", "v.csv"), pts)
