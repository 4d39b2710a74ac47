"""Trajectory readers: TUM, EuRoC, KITTI, generic CSV, OptiTrack Motive CSV and ROS bags.

:func:`read_trajectory` takes a source ``[FORMAT:]PATH[@SELECTOR]`` (syntax in
:mod:`loceval.readers.source`), sniffs the format from the content when no prefix names it
(:mod:`loceval.readers.sniff`), and dispatches to the reader. Bags are read by
:mod:`loceval.readers.rosbag`, imported only when a bag is read, so importing :mod:`loceval`
does not import rosbags.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Final

from loceval.errors import InputError, ReaderError
from loceval.readers._common import keeping_duplicate_stamps
from loceval.readers.csv import CSV_KEYS, read_csv
from loceval.readers.sniff import sniff_format
from loceval.readers.source import SourceSpec, TrajectoryFormat, parse_source, refuse_special_file
from loceval.readers.tum import read_tum
from loceval.trajectory import Trajectory

if TYPE_CHECKING:
    from loceval.readers.euroc import read_euroc
    from loceval.readers.kitti import read_kitti
    from loceval.readers.motive import read_motive
    from loceval.readers.rosbag import RemoteFile

__all__ = [
    "SourceSpec",
    "TrajectoryFormat",
    "keeping_duplicate_stamps",
    "parse_source",
    "read_csv",
    "read_euroc",
    "read_kitti",
    "read_motive",
    "read_stored_bag",
    "read_trajectory",
    "read_tum",
    "sniff_format",
]

_LAZY: Final[Mapping[str, str]] = {
    "read_euroc": "loceval.readers.euroc",
    "read_kitti": "loceval.readers.kitti",
    "read_motive": "loceval.readers.motive",
}
"""Readers imported on first use, so reading a TUM file does not load them."""


def __getattr__(name: str) -> object:
    """Return a reader of :data:`_LAZY`, importing its module on first use."""
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    msg = f"module {__name__!r} has no attribute {name!r}"
    raise AttributeError(msg)


_STAMP_SOURCES: Final = ("header", "receive")
_OPTIONS: Final[Mapping[TrajectoryFormat, tuple[str, ...]]] = {
    TrajectoryFormat.TUM: (),
    TrajectoryFormat.EUROC: (),
    TrajectoryFormat.KITTI: ("times",),
    TrajectoryFormat.CSV: (*CSV_KEYS, "time_unit", "length_unit"),
    TrajectoryFormat.MOTIVE: ("up",),
    TrajectoryFormat.BAG: (),
    TrajectoryFormat.POINTS: (),
}
_NO_SELECTOR_HINT: Final[Mapping[TrajectoryFormat, str]] = {
    TrajectoryFormat.TUM: "remove the '@' part",
    TrajectoryFormat.EUROC: "remove the '@' part",
    TrajectoryFormat.KITTI: "name a times file with @times=FILE",
    TrajectoryFormat.CSV: "map columns with @t=COLUMN,x=COLUMN,...",
}


def read_trajectory(
    source: str | SourceSpec,
    *,
    default_format: TrajectoryFormat | None = None,
    name: str = "",
    stamp: str = "header",
) -> Trajectory:
    """Read a trajectory from any supported source.

    Args:
        source: ``[FORMAT:]PATH[@SELECTOR]`` text or a parsed :class:`SourceSpec`.
        default_format: the format when the source names none; None sniffs it from the
            content (:func:`sniff_format`).
        name: the trajectory's name; defaults to the selector of a bag or Motive source,
            else the file name without suffix.
        stamp: for bags, ``"header"`` (message header stamps) or ``"receive"`` (the bag's
            receive times); files carry their own stamps and ignore it.

    Returns:
        The trajectory (int64 ns stamps, REP 103 axes, warnings of what the reader did).

    Raises:
        InputError: ``stamp`` is neither ``"header"`` nor ``"receive"``.
        ReaderError: the file is missing or unreadable, the format cannot be told, a
            selector or option does not fit the format, or the reader rejects the content.
    """
    _check_stamp(stamp)
    spec = (
        parse_source(source, default_format=default_format) if isinstance(source, str) else source
    )
    refuse_special_file(spec.path)
    fmt = spec.format or default_format or sniff_format(spec.path)
    label = str(SourceSpec(fmt, spec.path, spec.selector, spec.options))
    _check_options(spec, fmt, label=label)
    if not name:
        name = spec.selector or spec.path.stem
    if fmt is TrajectoryFormat.POINTS:
        msg = (
            f"{str(spec.path)!r} holds control points (id,x,y,z), not a trajectory; give it "
            "as the reference and the trajectories as estimates."
        )
        raise ReaderError(msg)
    if fmt is TrajectoryFormat.BAG:
        return _read_bag(spec, name=name, stamp=stamp)
    if fmt is TrajectoryFormat.MOTIVE:
        from loceval.readers.motive import read_motive  # noqa: PLC0415

        return read_motive(
            spec.path, rigid_body=spec.selector, up_axis=spec.options.get("up"), name=name
        )
    if spec.selector is not None:
        msg = (
            f"{fmt.value} sources take no selector, got {spec.selector!r} in {label!r}; "
            f"{_NO_SELECTOR_HINT[fmt]}."
        )
        raise ReaderError(msg)
    if fmt is TrajectoryFormat.TUM:
        return read_tum(spec.path, name=name)
    if fmt is TrajectoryFormat.EUROC:
        from loceval.readers.euroc import read_euroc  # noqa: PLC0415

        return read_euroc(spec.path, name=name)
    if fmt is TrajectoryFormat.KITTI:
        from loceval.readers.kitti import read_kitti  # noqa: PLC0415

        times = spec.options.get("times")
        return read_kitti(
            spec.path, times=_times_path(times, spec.path) if times else None, name=name
        )
    columns = {key: value for key, value in spec.options.items() if key in CSV_KEYS}
    return read_csv(
        spec.path,
        columns=columns,
        time_unit=spec.options.get("time_unit"),
        length_unit=spec.options.get("length_unit"),
        name=name,
    )


def read_stored_bag(
    spec: SourceSpec, file: RemoteFile, *, name: str = "", stamp: str = "header"
) -> Trajectory:
    """Read a bag source whose bytes are read by position from a store, not from its path.

    Args:
        spec: the source (format ``bag``); its path only names the file.
        file: the bag's bytes (an MCAP file or ROS 1 bag in a bucket).
        name: the trajectory's name; defaults to the selector.
        stamp: ``"header"`` or ``"receive"`` (see :func:`read_trajectory`).

    Raises:
        InputError: ``stamp`` is neither ``"header"`` nor ``"receive"``.
        ReaderError: as :func:`read_trajectory` for a bag.
    """
    _check_stamp(stamp)
    if spec.format is not TrajectoryFormat.BAG:
        msg = f"only a bag is read from a store, not the {spec.format} source {spec.path}"
        raise TypeError(msg)
    _check_options(spec, spec.format, label=str(spec))
    return _read_bag(spec, name=name, stamp=stamp, file=file)


def _check_stamp(stamp: str) -> None:
    if stamp not in _STAMP_SOURCES:
        msg = f"Unknown stamp source {stamp!r}; use 'header' or 'receive'."
        raise InputError(msg)


def _check_options(spec: SourceSpec, fmt: TrajectoryFormat, *, label: str) -> None:
    allowed = _OPTIONS[fmt]
    for key in spec.options:
        if key not in allowed:
            accepted = f"use {', '.join(allowed)}" if allowed else "it takes no options"
            msg = f"Unknown option {key!r} for the {fmt.value} source {label!r}; {accepted}."
            raise ReaderError(msg)


def _times_path(times: str, poses: Path) -> Path:
    """Return the KITTI times path as given, or next to the poses file if only that exists."""
    given = Path(times)
    beside = poses.parent / given
    if not given.is_absolute() and not given.exists() and beside.exists():
        return beside
    return given


def _read_bag(
    spec: SourceSpec, *, name: str, stamp: str, file: RemoteFile | None = None
) -> Trajectory:
    if not spec.selector:
        msg = (
            f"{str(spec.path)!r} is a bag; name a topic or tf chain, e.g. "
            f"{spec.path}@/amcl_pose; run `loceval inspect {spec.path}` to list them."
        )
        raise ReaderError(msg)
    from loceval.readers.rosbag import (  # noqa: PLC0415  (keeps rosbags out of `import loceval`)
        StampSource,
        read_bag_trajectory,
    )

    return read_bag_trajectory(
        spec.path if file is None else file, spec.selector, stamp=StampSource(stamp), name=name
    )
