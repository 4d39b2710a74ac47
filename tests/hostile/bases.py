"""One small valid input per format loceval reads, written with the shared test factories.

A :class:`Base` knows how to write its input into a folder, which of the input's lines are
header lines and data rows (for the text corruptions of :mod:`tests.hostile.corpus`), and
its :class:`Role`: what the input is used as, which decides the command that reads it.
:func:`write_companions` writes the valid files a role's command also needs (an estimate,
a survey, a reference walk), so each case folder is self-contained and every path the
commands get is relative to it.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Final

import numpy as np

from loceval.trajectory import Trajectory
from tests import bagfactory as bf
from tests.checkpoint_factory import grid_points, stop_and_go, write_points, write_visits
from tests.factories import (
    make_trajectory,
    perturb,
    write_csv,
    write_euroc,
    write_kitti,
    write_motive,
    write_tum,
)
from tests.radio_factory import (
    make_anchors,
    make_ranges,
    make_reference,
    write_anchors_csv,
    write_ranges_csv,
)

__all__ = [
    "BASES",
    "Base",
    "Role",
    "truth",
    "write_companions",
]

TEXT_BASES: Final = frozenset(
    {"tum", "euroc", "kitti", "csv", "motive", "points", "visits", "anchors", "ranges"}
)
"""The bases that are text tables."""
SEED: Final = 20240601
POSES: Final = 80
"""Poses of the trajectories: enough for every metric, few enough to run hundreds of times."""
ESTIMATE: Final = "est.txt"
"""The valid TUM estimate next to every trajectory case (the truth, perturbed)."""
CP_SURVEY: Final = "survey.csv"
CP_ESTIMATE: Final = "cp_est.txt"
WALK: Final = "walk.txt"
ANCHORS: Final = "anchors.csv"
RANGES: Final = "ranges.csv"
RANGING_END_S: Final = 12.0


class Role(StrEnum):
    """What an input is used as; decides the commands and requests that read it."""

    TRAJECTORY = "trajectory"
    """A reference trajectory: ``evaluate INPUT est.txt``."""
    POINTS = "points"
    """A control-point survey as the reference: ``evaluate INPUT cp_est.txt``."""
    VISITS = "visits"
    """A visits table: ``evaluate survey.csv cp_est.txt --visits INPUT``."""
    ANCHORS = "anchors"
    """A radio anchors table: ``ranging walk.txt --anchors INPUT --ranges ranges.csv``."""
    RANGES = "ranges"
    """A radio ranges table: ``ranging walk.txt --anchors anchors.csv --ranges INPUT``."""
    BUILDING = "building"
    """A building model: ``evaluate ref.txt est.txt --building INPUT``."""


@dataclass(frozen=True)
class Base:
    """A valid input of one format.

    Attributes:
        name: the format's short name (the first part of every case id).
        filename: the input's name in the case folder (a file, or a folder for ROS 2 bags).
        role: what the input is used as.
        write: writes the valid input into a folder and returns its path.
        header_lines: lines before the first data row (text formats).
        delimiter: the cell delimiter of data rows; None splits at whitespace.
        value_column: a numeric (non-time) cell of a data row.
        time_column: the time cell of a data row, None without one.
        name_column: a cell holding a name (an id), None without one.
        selector: appended to the input's source in ``evaluate`` (``@/gt`` for bags).
    """

    name: str
    filename: str
    role: Role
    write: Callable[[Path], Path]
    header_lines: int = 0
    delimiter: str | None = ","
    value_column: int = 1
    time_column: int | None = 0
    name_column: int | None = None
    selector: str = ""

    @property
    def text(self) -> bool:
        """Whether the input is a text table (the line-level corruptions apply)."""
        return self.name in TEXT_BASES


def truth() -> Trajectory:
    """Return the seeded truth every trajectory input holds (8 s at 10 Hz)."""
    return make_trajectory(np.random.default_rng(SEED), POSES, dt_ns=100_000_000)


def _estimate() -> Trajectory:
    return perturb(truth(), np.random.default_rng(SEED + 1), sigma_m=0.02)


def _stop_and_go() -> object:
    return stop_and_go(
        np.random.default_rng(SEED), grid_points(2, 3, 0.6), passes=1, dwell_s=1.5, rate_hz=10.0
    )


def _write_cp_estimate(path: Path) -> Path:
    rec = _stop_and_go()
    est = rec.estimate  # type: ignore[attr-defined]
    rows = [
        f"{int(t) // 10**9}.{int(t) % 10**9:09d} {x!r} {y!r} {z!r}"
        for t, (x, y, z) in zip(est.stamps_ns, est.positions_xyz.tolist(), strict=True)
    ]
    path.write_text("\n".join(rows) + "\n")
    return path


def _write_survey(path: Path) -> Path:
    return write_points(path, _stop_and_go().points)  # type: ignore[attr-defined]


def _write_visits(path: Path) -> Path:
    return write_visits(path, _stop_and_go())  # type: ignore[arg-type]


def _write_walk(path: Path) -> Path:
    walk = make_reference(rate_hz=10.0)
    keep = walk.stamps_ns <= walk.stamps_ns[0] + int((RANGING_END_S + 1.0) * 1e9)
    part = Trajectory(walk.stamps_ns[keep], walk.positions_xyz[keep], walk.quat_xyzw[keep])  # type: ignore[index]
    return write_tum(path, part)


def _write_anchors(path: Path) -> Path:
    return write_anchors_csv(path, make_anchors())


def _write_ranges(path: Path) -> Path:
    recording = make_ranges(np.random.default_rng(SEED), rate_hz=2.0, end_s=RANGING_END_S)
    return write_ranges_csv(path, recording.ranges)


def write_companions(folder: Path, role: Role) -> None:
    """Write the valid files the commands of ``role`` read besides the hostile input."""
    if role in {Role.TRAJECTORY, Role.BUILDING}:
        write_tum(folder / ESTIMATE, _estimate())
        write_tum(folder / "ref.txt", truth())
    elif role in {Role.POINTS, Role.VISITS}:
        _write_survey(folder / CP_SURVEY)
        _write_cp_estimate(folder / CP_ESTIMATE)
    else:
        _write_walk(folder / WALK)
        _write_anchors(folder / ANCHORS)
        _write_ranges(folder / RANGES)


def _poses() -> bf.Poses:
    t = truth()
    assert t.quat_xyzw is not None
    return bf.Poses(t.stamps_ns.copy(), t.positions_xyz.copy(), t.quat_xyzw.copy())


def _bag(fmt: str) -> Callable[[Path], Path]:
    def write(folder: Path) -> Path:
        records = bf.pose_records("/gt", bf.POSE, _poses())
        records.append(bf.Record("/chatter", bf.STRING, int(_poses().stamps_ns[0]), "hello"))
        return bf.write_bag(bf.bag_path(folder, fmt), records, fmt=fmt)

    return write


def _storage_file(fmt: str, suffix: str) -> Callable[[Path], Path]:
    """A ROS 2 bag's storage file alone (``rec.mcap`` / ``rec.db3``), without metadata.yaml."""

    def write(folder: Path) -> Path:
        bag = _bag(fmt)(folder / "bagdir")
        [storage] = sorted(bag.glob(f"*{suffix}"))
        return storage.rename(folder / f"rec{suffix}")

    return write


def _zipped(fmt: str) -> Callable[[Path], Path]:
    def write(folder: Path) -> Path:
        bag = _bag(fmt)(folder / "unzipped")
        if bag.is_dir():
            return bf.zip_directory(bag, folder / "rec.zip")
        return bf.zip_file(bag, folder / "rec.zip")

    return write


def _writer(func: Callable[[Path, Trajectory], Path]) -> Callable[[Path], Path]:
    def write(path: Path) -> Path:
        return func(path, truth())

    return write


def _at(filename: str, func: Callable[[Path], Path]) -> Callable[[Path], Path]:
    def write(folder: Path) -> Path:
        return func(folder / filename)

    return write


def _kitti(path: Path) -> Path:
    return write_kitti(path, truth(), times_path=path.with_name("times.txt"))


def _motive(path: Path) -> Path:
    return write_motive(
        path, {"Body": truth()}, markers=False, capture_start="2023-11-14 10.13.20.000 PM"
    )


def _obj(path: Path) -> Path:
    """A unit cube as OBJ (a building model trimesh reads)."""
    corners = [(x, y, z) for x in (0, 4) for y in (0, 4) for z in (0, 3)]
    faces = [(1, 2, 4), (1, 4, 3), (5, 7, 8), (5, 8, 6), (1, 5, 6), (1, 6, 2)]
    faces += [(3, 4, 8), (3, 8, 7), (1, 3, 7), (1, 7, 5), (2, 6, 8), (2, 8, 4)]
    lines = [f"v {x} {y} {z}" for x, y, z in corners] + [f"f {a} {b} {c}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def _dxf(path: Path) -> Path:
    """A square room as DXF lines (a floor plan ezdxf reads)."""
    import ezdxf

    doc = ezdxf.new()
    space = doc.modelspace()
    square = [(0, 0), (4, 0), (4, 4), (0, 4), (0, 0)]
    for a, b in itertools.pairwise(square):
        space.add_line(a, b)
    doc.saveas(path)
    return path


BASES: Final[dict[str, Base]] = {
    base.name: base
    for base in (
        Base("tum", "ref.tum.txt", Role.TRAJECTORY, _at("ref.tum.txt", _writer(write_tum)),
             header_lines=1, delimiter=None),
        Base("euroc", "data.csv", Role.TRAJECTORY, _at("data.csv", _writer(write_euroc)),
             header_lines=1),
        Base("kitti", "poses.txt", Role.TRAJECTORY, _at("poses.txt", _kitti), delimiter=None,
             value_column=3, time_column=None, selector="@times=times.txt"),
        Base("csv", "traj.csv", Role.TRAJECTORY, _at("traj.csv", _writer(write_csv)),
             header_lines=1),
        Base("motive", "take.csv", Role.TRAJECTORY, _at("take.csv", _motive), header_lines=7,
             value_column=2, time_column=1, selector="@Body"),
        Base("points", "points.csv", Role.POINTS, _at("points.csv", _write_survey),
             header_lines=1, time_column=None, name_column=0),
        Base("visits", "visits.csv", Role.VISITS, _at("visits.csv", _write_visits),
             header_lines=1, value_column=2, time_column=1, name_column=0),
        Base("anchors", "anchors_in.csv", Role.ANCHORS, _at("anchors_in.csv", _write_anchors),
             header_lines=1, time_column=None, name_column=0),
        Base("ranges", "ranges_in.csv", Role.RANGES, _at("ranges_in.csv", _write_ranges),
             header_lines=1, value_column=2, name_column=1),
        Base("bag1", "rec.bag", Role.TRAJECTORY, _bag("rosbag1"), selector="@/gt"),
        Base("db3dir", "rec", Role.TRAJECTORY, _bag("sqlite3"), selector="@/gt"),
        Base("mcapdir", "rec", Role.TRAJECTORY, _bag("mcap"), selector="@/gt"),
        Base("mcapfile", "rec.mcap", Role.TRAJECTORY, _storage_file("mcap", ".mcap"),
             selector="@/gt"),
        Base("db3file", "rec.db3", Role.TRAJECTORY, _storage_file("sqlite3", ".db3"),
             selector="@/gt"),
        Base("bagzip", "rec.zip", Role.TRAJECTORY, _zipped("sqlite3"), selector="@/gt"),
        Base("obj", "building.obj", Role.BUILDING, _at("building.obj", _obj)),
        Base("dxf", "plan.dxf", Role.BUILDING, _at("plan.dxf", _dxf)),
    )
}  # fmt: skip
"""Every base input, by name."""
