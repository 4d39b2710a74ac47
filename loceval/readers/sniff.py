"""Tell a trajectory file's format from its content (never from its name).

:func:`sniff_format` recognises bags by their magic bytes and text formats by their first
lines; :func:`loceval.readers.read_trajectory` calls it when a source names no format.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Final

from loceval.errors import ReaderError
from loceval.readers.points import looks_like_control_points
from loceval.readers.source import TrajectoryFormat, missing_file_error, refuse_special_file

__all__ = ["sniff_format"]

_HEAD_BYTES: Final = 64 * 1024
_BAG_MAGICS: Final = (
    b"#ROSBAG V2.0",  # ROS 1 bag
    b"\x89MCAP0\r\n",  # MCAP (ROS 2)
    b"SQLite format 3\x00",  # ROS 2 sqlite3 storage (.db3)
    b"PK\x03\x04",  # zip of a bag
)
_CSV_DELIMITERS: Final = (",", ";", "\t")


_WHITESPACE_FORMATS: Final[Mapping[int, TrajectoryFormat]] = {
    3: TrajectoryFormat.TUM,
    4: TrajectoryFormat.TUM,
    8: TrajectoryFormat.TUM,
    12: TrajectoryFormat.KITTI,
}
"""Rows of whitespace-separated numbers: format by the count per row."""


def sniff_format(path: Path) -> TrajectoryFormat:
    """Tell a file's trajectory format from its content (never from its name).

    Bags are recognised by their magic bytes (ROS 1 ``#ROSBAG V2.0``, MCAP, SQLite, zip) or,
    for directories, by a ``metadata.yaml`` (a ``metadata.yaml`` itself is a bag too, as for
    the bag reader); text files by their first lines: a Motive
    ``Format Version`` line, a EuRoC ``#timestamp`` header or comma-separated rows with
    integer nanosecond stamps, rows of 12 numbers (KITTI), rows of 8, 4 or 3 numbers (TUM),
    a control-point header ``id,x,y,z`` without a time column (points), or a header row
    followed by numbers (generic CSV).

    Args:
        path: the file or directory.

    Returns:
        The format.

    Raises:
        ReaderError: the path does not exist, is empty, or its content matches no format.
    """
    path = Path(path)
    refuse_special_file(path)
    if path.name == "metadata.yaml":
        return TrajectoryFormat.BAG  # the metadata of a ROS 2 bag names the bag
    if path.is_dir():
        if (path / "metadata.yaml").is_file():
            return TrajectoryFormat.BAG
        msg = (
            f"{str(path)!r} is a folder without a metadata.yaml, so not a ROS 2 bag; "
            "name a trajectory file or a bag folder."
        )
        raise ReaderError(msg)
    try:
        with path.open("rb") as fh:
            head = fh.read(_HEAD_BYTES)
    except FileNotFoundError as err:
        raise missing_file_error(path) from err
    except OSError as err:
        msg = f"Cannot read {str(path)!r} ({err.strerror}); check the path and its permissions."
        raise ReaderError(msg) from err
    if head.startswith(_BAG_MAGICS):
        return TrajectoryFormat.BAG
    if not _visible(head):
        what = "empty" if not head else "empty but for whitespace"
        msg = f"{str(path)!r} is {what}; give the file that holds the recording."
        raise ReaderError(msg)
    fmt = _sniff_text(head)
    if fmt is None and _comments_only(head):
        msg = (
            f"{str(path)!r} holds only comments (lines starting with #), no data rows; give "
            "the file that holds the recording."
        )
        raise ReaderError(msg)
    if fmt is None:
        msg = (
            f"Cannot tell the format of {str(path)!r} from its first lines; name it with a "
            f"prefix, e.g. tum:{path} (one of {', '.join(f.value for f in TrajectoryFormat)})."
        )
        raise ReaderError(msg)
    return fmt


def _visible(head: bytes) -> bool:
    """Whether the text holds anything but whitespace, Unicode's separators included.

    Python's ``str.strip`` also takes the ASCII separators 0x1c-0x1f and U+0085, U+2028:
    a file of those alone is as blank as one of spaces.
    """
    return bool(head.decode("utf-8-sig", errors="replace").strip())


def _sniff_text(head: bytes) -> TrajectoryFormat | None:
    if not _visible(head) or b"\x00" in head:
        return None
    text = head.decode("utf-8-sig", errors="replace")
    if "\r" in text and "\n" not in text:
        text = text.replace("\r", "\n")  # old Mac line ends, as load_text reads them
    if len(head) == _HEAD_BYTES and "\n" in text:
        text = text[: text.rindex("\n")]  # drop the cut-off last line
    lines = [line.strip() for line in text.split("\n") if line.strip()]
    first = lines[0] if lines else ""  # blank but for a cut-off last line: no data below
    if first.split(",", 1)[0].strip().lower() == "format version":
        return TrajectoryFormat.MOTIVE
    if _is_euroc_header(first):
        return TrajectoryFormat.EUROC
    data = [line for line in lines if not line.startswith("#")]
    if not data:
        return None
    words = data[0].split()
    if "," not in data[0] and ";" not in data[0] and _all_numbers(words):
        return _WHITESPACE_FORMATS.get(len(words))
    comments = [line for line in lines[: lines.index(data[0])] if line.startswith("#")]
    return _sniff_delimited(data, comments[-1] if comments else None)


def _sniff_delimited(data: list[str], last_comment: str | None) -> TrajectoryFormat | None:
    """Tell rows that are not whitespace-separated numbers: CSV with a header, or EuRoC."""
    row = data[0]
    delimiter = max(_CSV_DELIMITERS, key=row.count)
    if not row.count(delimiter):
        # a whitespace-separated header row ("t x y z") over rows of numbers
        header_over_numbers = len(data) > 1 and _all_numbers(data[1].split())
        return TrajectoryFormat.CSV if header_over_numbers else None
    cells = [cell.strip() for cell in row.split(delimiter)]
    if not _all_numbers(cells):
        if looks_like_control_points(row):
            return TrajectoryFormat.POINTS
        return TrajectoryFormat.EUROC if _is_euroc_header(row) else TrajectoryFormat.CSV
    if last_comment is not None and delimiter in last_comment:
        return TrajectoryFormat.CSV  # a '#'-prefixed header row
    headerless_euroc = delimiter == "," and len(cells) >= 8 and cells[0].isdigit()
    return TrajectoryFormat.EUROC if headerless_euroc else None


def _comments_only(head: bytes) -> bool:
    """Whether every non-blank line of a (whole, short) file is a ``#`` comment."""
    if len(head) == _HEAD_BYTES:
        return False  # the first 64 KiB only: the data may come later
    lines = [line.strip() for line in head.split(b"\n") if line.strip()]
    return bool(lines) and all(line.startswith(b"#") for line in lines)


def _is_euroc_header(line: str) -> bool:
    cells = [cell.strip().lower() for cell in line.lstrip("#").split(",")]
    return len(cells) >= 4 and cells[0].startswith("timestamp") and "p_rs_r_x" in cells[1]


def _all_numbers(cells: list[str]) -> bool:
    try:
        for cell in cells:
            float(cell)
    except ValueError:
        return False
    return bool(cells)
