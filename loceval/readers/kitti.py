"""KITTI odometry poses: the 3x4 matrix ``[R|t]`` row by row, with an optional times file."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Final

import numpy as np

from loceval.core.arrays import FloatArray, IntArray, StampsNs
from loceval.core.rotation import Rotation
from loceval.errors import ReaderError
from loceval.readers._common import build_trajectory
from loceval.readers.source import SourceSpec, TrajectoryFormat
from loceval.readers.text import NS_PER_S, load_bytes, parse_table, stamps_from_values
from loceval.trajectory import Trajectory

__all__ = ["KITTI_ROTATION_TOLERANCE", "read_kitti"]

KITTI_ROTATION_TOLERANCE: Final = 1e-2
"""Largest ``|R Rᵀ - I|`` entry and ``|det R - 1|`` accepted in a KITTI pose; smaller
deviations (print rounding) are projected onto the nearest rotation."""
_KITTI_HINT: Final = "every KITTI line holds the 12 numbers of a 3x4 [R|t] matrix, row by row"


def read_kitti(path: Path, *, times: Path | None = None, name: str = "") -> Trajectory:
    """Read KITTI odometry poses: 12 numbers per line, the 3x4 matrix ``[R|t]`` row by row.

    Poses stay in the KITTI camera frame (x right, y down, z forward). With a times file
    (one time in seconds per line, as KITTI's ``times.txt``) pose i is stamped with line i.
    Without one, pose i is stamped i seconds and a warning says so: two KITTI files without
    times then pair by index, which is what KITTI evaluation does.

    Args:
        path: the poses file.
        times: the times file, or None.
        name: the trajectory's name.

    Returns:
        The trajectory; ``source`` is ``kitti:PATH`` or ``kitti:PATH@times=TIMES``.

    Raises:
        ReaderError: a file is missing or unreadable, a line does not hold 12 numbers, a
            rotation is far from orthonormal, the times and poses differ in number, or
            fewer than three poses remain.
    """
    path = Path(path)
    where = str(path)
    table = parse_table(
        load_bytes(path), where=where, delimiter=None, hint=_KITTI_HINT, comments="#"
    )
    n = len(table)
    width = table.values.shape[1] if n else 12
    if width != 12:
        msg = (
            f"{where}, line {int(table.lines[0])}: {width} values per line, but "
            f"{_KITTI_HINT}; check the file or name its format with a prefix."
        )
        raise ReaderError(msg)
    matrices = table.values.reshape(n, 3, 4)
    bad_rows = np.flatnonzero(~np.isfinite(table.values).all(axis=1))
    if bad_rows.size:
        msg = (
            f"{where}, line {int(table.lines[bad_rows[0]])}: the pose holds NaN or inf; "
            "remove that line or re-export the file."
        )
        raise ReaderError(msg)
    rotations = matrices[:, :, :3]
    _check_rotations(rotations, table.lines, where=where)
    quat = Rotation.from_matrix(rotations).as_quat() if n else np.zeros((0, 4))
    positions = matrices[:, :, 3]
    notes: list[str] = []
    options: dict[str, str] = {}
    if times is None:
        stamps = np.arange(n, dtype=np.int64) * NS_PER_S
        notes.append(
            f"{where}: no times file, so pose i is stamped i seconds and poses are matched "
            "by index; give one with kitti:PATH@times=TIMES for real stamps."
        )
    else:
        times = Path(times)
        options["times"] = str(times)
        stamps = _read_kitti_times(times, n, poses_where=where)
    trajectory = build_trajectory(
        stamps,
        positions,
        quat,
        where=where,
        line_numbers=table.lines,
        name=name,
        source=str(SourceSpec(TrajectoryFormat.KITTI, path, None, options)),
        warnings=tuple(notes),
    )
    return replace(trajectory, indexed=True) if times is None else trajectory


def _read_kitti_times(times: Path, n_poses: int, *, poses_where: str) -> StampsNs:
    where = str(times)
    hint = "a KITTI times file holds one time in seconds per line"
    table = parse_table(load_bytes(times), where=where, delimiter=None, hint=hint, comments="#")
    if len(table) and table.values.shape[1] != 1:
        msg = (
            f"{where}, line {int(table.lines[0])}: {table.values.shape[1]} values, but {hint}; "
            "check that this is the times file."
        )
        raise ReaderError(msg)
    if len(table) != n_poses:
        msg = (
            f"{where} holds {len(table)} times but {poses_where} holds {n_poses} poses; "
            "use the times file of this sequence."
        )
        raise ReaderError(msg)
    seconds = table.values[:, 0] if len(table) else np.zeros(0)
    return stamps_from_values(
        seconds, ns_per_unit=NS_PER_S, lines=table.lines, where=where, unit="s"
    )


def _check_rotations(rotations: FloatArray, lines: IntArray, *, where: str) -> None:
    if not len(rotations):
        return
    gram_error = np.abs(rotations @ rotations.transpose(0, 2, 1) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(rotations)
    bad = np.flatnonzero(
        (gram_error > KITTI_ROTATION_TOLERANCE) | (np.abs(det - 1.0) > KITTI_ROTATION_TOLERANCE)
    )
    if bad.size:
        i = int(bad[0])
        msg = (
            f"{where}, line {int(lines[i])}: the 3x3 block is not a rotation (determinant "
            f"{float(det[i]):.6g}, {bad.size} such lines); check that the file holds KITTI "
            "poses [R|t] row by row."
        )
        raise ReaderError(msg)
