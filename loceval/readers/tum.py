"""The TUM RGB-D trajectory format: ``t x y z qx qy qz qw`` per line, stamps in seconds."""

from __future__ import annotations

from pathlib import Path
from typing import Final

import numpy as np

from loceval.errors import ReaderError
from loceval.readers._common import build_trajectory
from loceval.readers.source import SourceSpec, TrajectoryFormat
from loceval.readers.text import (
    NS_PER_S,
    load_bytes,
    parse_table,
    positions_and_quat,
    stamps_from_values,
)
from loceval.trajectory import Trajectory

__all__ = ["read_tum"]

_TUM_HINT: Final = "every TUM line holds t x y z qx qy qz qw (8 values), t x y z (4) or t x y (3)"


def read_tum(path: Path, *, name: str = "") -> Trajectory:
    """Read a TUM trajectory: ``t x y z qx qy qz qw`` per line, stamps in seconds.

    ``#`` comments and blank lines are skipped. Position-only files with ``t x y z`` or
    ``t x y`` (z = 0) lines are accepted; every line must have the same number of values.

    Args:
        path: the file.
        name: the trajectory's name.

    Returns:
        The trajectory; ``source`` is ``tum:PATH``.

    Raises:
        ReaderError: the file is missing or unreadable, a line has the wrong number of
            values or a non-number, a value is NaN/inf, a quaternion is not unit, or
            fewer than three poses remain.
    """
    path = Path(path)
    where = str(path)
    table = parse_table(load_bytes(path), where=where, delimiter=None, hint=_TUM_HINT, comments="#")
    values = table.values
    width = values.shape[1] if values.ndim == 2 else 0
    if len(table) and width not in {3, 4, 8}:
        msg = (
            f"{where}, line {int(table.lines[0])}: {width} values per line, but {_TUM_HINT}; "
            "check the file or name its format with a prefix."
        )
        raise ReaderError(msg)
    stamps = stamps_from_values(
        values[:, 0] if len(table) else np.zeros(0),
        ns_per_unit=NS_PER_S,
        lines=table.lines,
        where=where,
        unit="s",
    )
    positions, quat = positions_and_quat(values, width, quat_cols=[4, 5, 6, 7])
    return build_trajectory(
        stamps,
        positions,
        quat,
        where=where,
        line_numbers=table.lines,
        name=name,
        source=str(SourceSpec(TrajectoryFormat.TUM, path)),
    )
