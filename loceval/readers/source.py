r"""Name a trajectory source: :class:`SourceSpec`, parsed from ``[FORMAT:]PATH[@SELECTOR]``.

A source is written ``[FORMAT:]PATH[@SELECTOR]``:

- ``FORMAT:`` is optional and only counts when it is one of :class:`TrajectoryFormat`'s
  values (``tum``, ``euroc``, ``kitti``, ``csv``, ``motive``, ``bag``, ``points``), so
  ``C:\data`` or ``run:2.txt`` stay paths. Without it the format is sniffed from the content
  (:func:`loceval.readers.sniff.sniff_format`).
- ``@SELECTOR`` is optional: comma-separated items, where ``KEY=VALUE`` items are options
  and at most one plain item is the selector. What each format accepts:

  - ``bag``: a topic or a tf chain, ``run.mcap@/amcl_pose``, ``run.bag@tf:map:base_link``.
  - ``motive``: the rigid body, ``motive:take.csv@RigidBody1``; option ``up=y|z`` for the
    export's up axis, ``motive:take.csv@Drone,up=z``.
  - ``kitti``: the times file, ``kitti:00.txt@times=times.txt`` (a relative times path
    that does not exist as given is looked up next to the poses file).
  - ``csv``: column mappings ``KEY=HEADER`` for the keys ``t x y z qx qy qz qw``, plus
    ``time_unit=s|ms|us|ns`` and ``length_unit=m|cm|mm``, e.g.
    ``csv:log.csv@t=time_s,x=px,y=py,z=pz``. Unmapped keys use the recognised names.
  - ``tum``, ``euroc`` and ``points`` (control points, a reference only) take nothing
    after ``@``.

Existing paths win over this syntax: a file literally named ``tum:a@b.txt`` is read as
that file, and ``data@2024/run.txt@/odom`` splits at the last ``@`` whose left side exists.
"""

from __future__ import annotations

import stat
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from types import MappingProxyType
from typing import Final

from loceval.errors import ReaderError

__all__ = [
    "SourceSpec",
    "TrajectoryFormat",
    "missing_file_error",
    "parse_source",
    "refuse_special_file",
]


class TrajectoryFormat(StrEnum):
    """The trajectory formats :func:`loceval.readers.read_trajectory` reads."""

    TUM = "tum"
    """Whitespace-separated ``t x y z qx qy qz qw`` (seconds), or ``t x y z`` / ``t x y``."""
    EUROC = "euroc"
    """EuRoC ground-truth CSV: nanosecond stamps, ``x y z`` then ``qw qx qy qz``."""
    KITTI = "kitti"
    """KITTI odometry poses: 12 numbers per line (3x4 row-major), optional times file."""
    CSV = "csv"
    """A CSV with a header row, read through a column mapping."""
    MOTIVE = "motive"
    """An OptiTrack Motive CSV export."""
    BAG = "bag"
    """A ROS 1 bag, ROS 2 bag (directory, .db3, .mcap) or a zip of one."""
    POINTS = "points"
    """Surveyed control points ``id,x,y,z`` (a reference, not a trajectory)."""

    @property
    def shape(self) -> str:
        """What a file of this format holds, in words a person checks a file against."""
        return _SHAPES[self]


_SHAPES: Final = MappingProxyType(
    {
        TrajectoryFormat.TUM: "TUM: a line per pose, t x y z qx qy qz qw separated by spaces, "
        "t in seconds",
        TrajectoryFormat.EUROC: "EuRoC: the ground-truth CSV, t in nanoseconds, then x y z "
        "and qw qx qy qz",
        TrajectoryFormat.KITTI: "KITTI: a line per pose, the 12 numbers of a 3x4 matrix",
        TrajectoryFormat.CSV: "CSV: a header row naming the columns t, x, y, z (qx qy qz qw "
        "optional)",
        TrajectoryFormat.MOTIVE: "Motive: OptiTrack Motive's CSV export of a take",
        TrajectoryFormat.BAG: "ROS bag: .bag, .db3 or .mcap, or a bag folder as .zip",
        TrajectoryFormat.POINTS: "surveyed points: a CSV of id,x,y,z",
    }
)
"""The formats' shapes (:attr:`TrajectoryFormat.shape`), for a person choosing a file."""


@dataclass(frozen=True, slots=True)
class SourceSpec:
    """A parsed ``[FORMAT:]PATH[@SELECTOR]`` source.

    Attributes:
        format: the format named by the prefix (or the default), None to sniff it.
        path: the file or bag directory.
        selector: the topic, tf chain or rigid body name, if given.
        options: ``KEY=VALUE`` items after ``@`` (read-only).
    """

    format: TrajectoryFormat | None
    path: Path
    selector: str | None = None
    options: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        """Store the options as a read-only copy."""
        object.__setattr__(self, "path", Path(self.path))
        object.__setattr__(self, "options", MappingProxyType(dict(self.options)))

    def __str__(self) -> str:
        """Return the source in the syntax :func:`parse_source` reads."""
        prefix = f"{self.format.value}:" if self.format is not None else ""
        items = [self.selector] if self.selector else []
        items += [f"{key}={value}" for key, value in self.options.items()]
        suffix = "@" + ",".join(items) if items else ""
        return f"{prefix}{self.path}{suffix}"


def parse_source(text: str, *, default_format: TrajectoryFormat | None = None) -> SourceSpec:
    """Parse ``[FORMAT:]PATH[@SELECTOR]`` (see the module docstring for the syntax).

    Args:
        text: the source as the user wrote it.
        default_format: the format when the text has no ``FORMAT:`` prefix; None to
            sniff it from the content later.

    Returns:
        The parsed source. The path is not checked here, except to tell a path that
        contains ``:`` or ``@`` from the syntax.

    Raises:
        ReaderError: the text is empty, or the part after ``@`` holds two selectors.
    """
    if not text.strip():
        msg = "Empty source; give a file, e.g. tum:groundtruth.txt or run.mcap@/odom."
        raise ReaderError(msg)
    if _exists(text):
        return SourceSpec(default_format, Path(text))
    fmt = default_format
    rest = text
    head, colon, tail = text.partition(":")
    if colon and head.lower() in {f.value for f in TrajectoryFormat}:
        fmt = TrajectoryFormat(head.lower())
        rest = tail
    path_text, suffix = _split_selector(rest)
    if not path_text.strip():
        msg = f"Source {text!r} names no file; give one, e.g. tum:groundtruth.txt."
        raise ReaderError(msg)
    selector, options = _parse_suffix(suffix, text=text)
    return SourceSpec(fmt, Path(path_text), selector, options)


def _exists(text: str) -> bool:
    """Whether a path exists; names the OS cannot even look up (too long, NUL) do not."""
    try:
        return bool(text) and Path(text).exists()
    except (OSError, ValueError):
        return False


def _split_selector(rest: str) -> tuple[str, str | None]:
    """Split ``PATH@SUFFIX`` at the last ``@`` whose left side exists, else the first."""
    if "@" not in rest or _exists(rest):
        return rest, None
    positions = [i for i, char in enumerate(rest) if char == "@"]
    for i in reversed(positions):
        if _exists(rest[:i]):
            return rest[:i], rest[i + 1 :]
    return rest[: positions[0]], rest[positions[0] + 1 :]


def _parse_suffix(suffix: str | None, *, text: str) -> tuple[str | None, dict[str, str]]:
    if suffix is None:
        return None, {}
    selector: str | None = None
    options: dict[str, str] = {}
    for raw in suffix.split(","):
        item = raw.strip()
        if not item:
            continue
        key, equals, value = item.partition("=")
        if equals:
            options[key.strip().lower()] = value.strip()
        elif selector is None:
            selector = item
        else:
            msg = (
                f"Source {text!r} names two selectors, {selector!r} and {item!r}; "
                "give one topic, tf chain or rigid body after '@'."
            )
            raise ReaderError(msg)
    return selector, options


def missing_file_error(path: Path) -> ReaderError:
    """Return the error for a path that does not exist."""
    return ReaderError(f"No such file: {str(path)!r}; check the path.")


def refuse_special_file(path: Path) -> None:
    """Refuse pipes, sockets and devices with a ReaderError.

    Readers open a file more than once (sniffing, then reading), which a pipe cannot serve,
    and reading a pipe that has no writer never ends. A missing path passes: the reader
    reports it with the path.
    """
    try:
        mode = Path(path).stat().st_mode
    except OSError:
        return
    if stat.S_ISDIR(mode) or stat.S_ISREG(mode):
        return
    msg = (
        f"{str(path)!r} is a pipe or device, not a file; save the data to a file first "
        "(e.g. cmd > run.txt) and name that file."
    )
    raise ReaderError(msg)
