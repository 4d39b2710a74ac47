"""Open a bag through rosbags and read the raw messages of chosen connections.

Every rosbags error, damaged-file error and missing file becomes a
:class:`~loceval.errors.ReaderError` here (:func:`converted`).
"""

from __future__ import annotations

import os
import sqlite3
import struct
import sys
import sysconfig
from collections.abc import Callable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Final, Protocol, cast, runtime_checkable

import apsw  # rosbags' SQLite driver: a damaged .db3 raises its errors, not sqlite3's
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import Connection
from rosbags.rosbag1 import ReaderError as Rosbag1ReaderError
from rosbags.rosbag2 import Reader as Rosbag2Reader
from rosbags.rosbag2 import ReaderError as Rosbag2ReaderError
from rosbags.rosbag2 import storage_mcap
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, TypesysError, get_typestore
from rosbags.typesys.store import Typestore

if sys.version_info >= (3, 14):
    from compression.zstd import ZstdError
else:  # rosbags depends on backports.zstd before Python 3.14
    from backports.zstd import ZstdError

from loceval.errors import ReaderError
from loceval.readers._archive import extracted_bag
from loceval.readers._mcap import RandomAccess, index_serves, read_indexed_messages
from loceval.readers.rosbag.messages import TF_MSGTYPE, BagFormat

__all__ = [
    "Bag",
    "converted",
    "deserialize",
    "is_static_topic",
    "is_tf",
    "listing",
    "normalize_msgtype",
    "open_bag",
    "raw_messages",
    "serves_by_index",
]

_MAX_LISTED = 40

# rosbags reports damaged files through its own errors ...
_LIBRARY_ERRORS: Final = (
    AnyReaderError,
    Rosbag1ReaderError,
    Rosbag2ReaderError,
    SerdeError,
    TypesysError,
    sqlite3.Error,
    apsw.Error,
    ZstdError,
)
# ... and through these builtins when a record is cut short or garbled (struct unpacking, text
# decoding, sqlite, decompressors) ...
_DATA_ERRORS: Final = (
    struct.error,
    EOFError,
    OSError,
    ValueError,
    IndexError,
    OverflowError,
    MemoryError,  # a damaged length field: the reader tries to allocate exabytes
)
# ... and, from inside rosbags only, through these. Raised by loceval's own code they are bugs,
# not damage, and :func:`converted` lets them through.
_LIBRARY_BUG_ERRORS: Final = (
    RuntimeError,
    KeyError,
    AssertionError,
    TypeError,  # rosbags' MCAP reader calls ord() on an empty read of a truncated file
)
_LIBRARY_DIRS: Final = tuple(
    Path(sysconfig.get_path(name)).resolve()
    for name in ("stdlib", "platstdlib", "purelib", "platlib")
)
"""Where the standard library and installed packages (rosbags, zstandard, ...) live."""
_LOCEVAL_DIR: Final = Path(__file__).resolve().parents[2]


def _raised_by_library(err: BaseException) -> bool:
    """Return whether ``err`` was raised inside a library (rosbags, the stdlib), not by us.

    The innermost Python frame decides: in an installed package or the standard library, and
    not in loceval itself, it is the library's report of a damaged file; anywhere else (our
    code, a caller's) it is a bug that must not read as "the bag looks damaged".
    """
    tb = err.__traceback__
    if tb is None:
        return False
    while tb.tb_next is not None:
        tb = tb.tb_next
    filename = tb.tb_frame.f_code.co_filename
    if filename.startswith("<frozen "):  # the standard library's frozen modules (os, ...)
        return True
    where = Path(filename).resolve()
    if where.is_relative_to(_LOCEVAL_DIR):
        return False
    return any(where.is_relative_to(folder) for folder in _LIBRARY_DIRS)


def _read_within_file(read_exact: Callable[[BinaryIO, int], bytes]) -> Callable[..., bytes]:
    """Wrap rosbags' MCAP ``read_exact`` so a record longer than the rest of the file is refused.

    A damaged MCAP file holds garbage record lengths; unchecked, ``read(size)`` asks for
    exabytes (MemoryError) or, worse, for gigabytes that are allocated and filled.
    """

    def read_within_file(bio: BinaryIO, size: int) -> bytes:
        pos = bio.tell()
        end = _file_size(bio)
        if size > end - pos:
            msg = f"Truncated record at offset {pos}: expected {size} bytes, got {end - pos}."
            raise Rosbag2ReaderError(msg)
        return read_exact(bio, size)

    return read_within_file


def _file_size(bio: BinaryIO) -> int:
    """Return the size of an open file without moving in it.

    Seeking to the end and back would do, but a buffered reader drops its buffer at every
    seek: over an object in a bucket (:class:`service.blobs.ranged.RangedFile`, which knows
    its size) each record of an MCAP summary then cost a new ranged request.
    """
    try:
        return os.fstat(bio.fileno()).st_size
    except (OSError, AttributeError):  # io.UnsupportedOperation is an OSError
        pass
    size = getattr(getattr(bio, "raw", bio), "size", None)
    if isinstance(size, int):
        return size
    pos = bio.tell()
    end = bio.seek(0, os.SEEK_END)
    bio.seek(pos)
    return end


if storage_mcap.read_exact.__name__ != "read_within_file":  # once, even if reimported
    storage_mcap.read_exact = _read_within_file(storage_mcap.read_exact)


# --- Opening bags.


@runtime_checkable
class RemoteFile(RandomAccess, Protocol):
    """A bag file read by position from elsewhere (an object store), not from a local path.

    It is a path for rosbags' readers (``open()`` gives a seekable binary file, the way
    rosbags' ``RPath`` protocol asks) and :class:`~loceval.readers._mcap.RandomAccess` for
    the MCAP index reader, so an MCAP file or a ROS 1 bag is read piece by piece: its index,
    then only the chunks or messages wanted.
    """

    @property
    def name(self) -> str:
        """The file name."""
        ...

    @property
    def suffix(self) -> str:
        """The file name's suffix (``.mcap`` or ``.bag``)."""
        ...

    def exists(self) -> bool:
        """Whether the file exists."""
        ...

    def is_dir(self) -> bool:
        """False: a remote file is no folder."""
        ...

    def open(self, mode: str = "rb") -> BinaryIO:
        """Open it for reading."""
        ...


@dataclass(frozen=True, slots=True, eq=False)
class Bag:
    """An open bag: the reader, its label and storage format, and the paths opened."""

    reader: AnyReader
    label: str
    storage_format: BagFormat
    archive: str
    paths: tuple[Path, ...]


def serves_by_index(file: RemoteFile) -> bool:
    """Return whether a remote bag is read for a few topics without reading most of it.

    True for an MCAP file with a summary, chunk indexes and uncompressed chunks (its
    messages are found through the index: :func:`raw_messages`); False for anything else,
    which is read chunk after chunk (a ROS 1 bag's chunks mix every topic).
    """
    return file.suffix.lower() == ".mcap" and index_serves(file)


@contextmanager
def open_bag(path: Path | Sequence[Path] | RemoteFile) -> Iterator[Bag]:
    """Open a bag (file, folder, split set or zip, or a remote file) and yield it; close it."""
    if isinstance(path, RemoteFile):
        with _open_remote(path) as bag:
            yield bag
        return
    paths = _as_paths(path)
    label = ",".join(p.name for p in paths)
    for p in paths:
        if not p.exists():
            msg = f"Bag {str(p)!r} does not exist; check the path (a ROS 2 bag is a folder)."
            raise ReaderError(msg)
    with ExitStack() as stack:
        archive = ""
        if len(paths) == 1 and paths[0].is_file() and paths[0].suffix.lower() == ".zip":
            paths = tuple(stack.enter_context(extracted_bag(paths[0])))
            archive = "zip"
        paths = tuple(_storage_path(p) for p in paths)
        if len(paths) > 1 and any(p.suffix != ".bag" for p in paths):
            names = ", ".join(p.name for p in paths)
            msg = (
                f"Only ROS 1 bags (.bag) can be read as a split set, got {names!r}; pass one "
                "ROS 2 bag directory or the .bag files of one recording."
            )
            raise ReaderError(msg)
        if paths[0].is_dir() and not (paths[0] / "metadata.yaml").is_file():
            inside = listing(sorted(x.name for x in paths[0].iterdir())) or "nothing"
            msg = (
                f"Folder {str(paths[0])!r} has no metadata.yaml, so it is no ROS 2 bag; it "
                f"holds: {inside}; pass the bag folder or a bag file."
            )
            raise ReaderError(msg)
        if paths[0].is_file() and paths[0].suffix.lower() not in {".bag", ".mcap", ".db3"}:
            msg = (
                f"File {str(paths[0])!r} is not a bag; pass a .bag, .mcap or .db3 file, a ROS "
                "2 bag folder or a .zip of one."
            )
            raise ReaderError(msg)
        with converted(label):
            reader = _open_reader(list(paths), stack)
        yield Bag(reader, label, _storage_format(paths), archive, paths)


@contextmanager
def _open_remote(file: RemoteFile) -> Iterator[Bag]:
    """Open an MCAP file or a ROS 1 bag that is read by position (its index, then parts)."""
    formats = {".mcap": BagFormat.ROSBAG2_MCAP, ".bag": BagFormat.ROSBAG1}
    storage_format = formats.get(file.suffix.lower())
    if storage_format is None:
        msg = (
            f"Bag {file.name!r} is read from a remote store, which serves .mcap files and ROS 1 "
            ".bag files; copy other bags (.db3, zipped folders) to a local file first."
        )
        raise ReaderError(msg)
    with ExitStack() as stack:
        with converted(file.name):
            reader = _open_reader([cast("Path", file)], stack)  # rosbags takes any RPath
        yield Bag(reader, file.name, storage_format, "", ())


def _open_reader(paths: list[Path], stack: ExitStack) -> AnyReader:
    """Open an AnyReader; fall back to ROS 2 Humble's types for bags without definitions.

    The fallback typestore takes a tenth of a second to build, so it is only built for the
    bags that need it: old ROS 2 bags without embedded message definitions make the first
    open fail, and the second open then gets it.
    """
    reader = AnyReader(paths)
    try:
        reader.open()
    except AnyReaderError:
        reader = AnyReader(paths, default_typestore=_default_typestore())
        reader.open()
    stack.callback(reader.close)
    return reader


def _as_paths(path: Path | Sequence[Path]) -> tuple[Path, ...]:
    if isinstance(path, str | os.PathLike):
        return (Path(path),)
    paths = tuple(Path(p) for p in path)
    if not paths:
        msg = "No bag path given; pass a bag file, a ROS 2 bag folder or a zip of one."
        raise ReaderError(msg)
    return paths


def _storage_path(path: Path) -> Path:
    """Return what rosbags opens: a .db3 or metadata.yaml inside a bag opens the folder."""
    if path.name == "metadata.yaml" and path.is_file():
        return path.parent
    if path.suffix == ".db3" and (path.parent / "metadata.yaml").is_file():
        return path.parent
    return path


def _storage_format(paths: tuple[Path, ...]) -> BagFormat:
    first = paths[0]
    if first.suffix == ".bag":
        return BagFormat.ROSBAG1
    if first.suffix == ".mcap":
        return BagFormat.ROSBAG2_MCAP
    if first.is_dir() and any(".mcap" in x.suffixes for x in first.iterdir()):
        return BagFormat.ROSBAG2_MCAP
    return BagFormat.ROSBAG2_SQLITE3


@contextmanager
def converted(label: str) -> Iterator[None]:
    """Turn rosbags' (and damaged files') exceptions into ReaderError."""
    try:
        yield
    except ReaderError:
        raise
    except FileNotFoundError as err:
        msg = f"Bag {label!r} is incomplete ({err}); copy the whole bag folder or file."
        raise ReaderError(msg) from err
    except (*_LIBRARY_ERRORS, *_DATA_ERRORS, *_LIBRARY_BUG_ERRORS) as err:
        if not isinstance(err, _LIBRARY_ERRORS + _DATA_ERRORS) and not _raised_by_library(err):
            raise  # a bug of loceval's own, not a damaged bag
        detail = " ".join(str(err).split())  # parsers' reports span lines (YAML carets)
        msg = (
            f"Bag {label!r} cannot be read; it looks truncated, damaged or of an unknown "
            f"format ({type(err).__name__}: {detail}); re-copy the file, or reindex it "
            "('rosbag reindex' / 'ros2 bag reindex')."
        )
        raise ReaderError(msg) from err


def _default_typestore() -> Typestore:
    return get_typestore(Stores.ROS2_HUMBLE)


def normalize_msgtype(msgtype: str) -> str:
    """Return ``pkg/msg/Type`` for ``pkg/Type`` (ROS 1) and ``pkg/msg/Type``."""
    parts = msgtype.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return msgtype


def is_tf(conn: Connection) -> bool:
    """Whether a connection carries tf2_msgs/msg/TFMessage."""
    return normalize_msgtype(conn.msgtype) == TF_MSGTYPE


def is_static_topic(topic: str) -> bool:
    """Whether a tf topic holds static links (its last name part is ``tf_static``)."""
    return topic.rstrip("/").rsplit("/", 1)[-1] == "tf_static"


# --- Reading messages.


def raw_messages(
    bag: Bag, connections: Sequence[Connection]
) -> Iterator[tuple[Connection, int, bytes]]:
    """Yield ``(connection, receive_ns, rawdata)`` of the connections.

    ROS 2 bags yield in receive order. ROS 1 bags yield topic by topic, each in receive
    order: rosbags reloads a chunk whenever consecutive messages lie in different chunks,
    and merging topics recorded into separate chunks (as in bags written topic by topic)
    made that thirty times slower.

    Checks that as many messages came out as the bag's index recorded: damaged chunks can
    otherwise vanish silently.
    """
    if not connections:
        return
    counts: dict[str, int] = dict.fromkeys((c.topic for c in connections), 0)
    if bag.reader.is2:
        groups = [list(connections)]
    else:
        groups = [[c for c in connections if c.topic == topic] for topic in counts]
    for group in groups:
        indexed = _indexed_mcap_messages(bag, group)
        with converted(bag.label):
            source = indexed if indexed is not None else bag.reader.messages(group)
            for conn, receive_ns, raw in source:
                counts[conn.topic] += 1
                yield conn, receive_ns, raw
    for topic, seen in counts.items():
        recorded = sum(c.msgcount for c in connections if c.topic == topic)
        if seen < recorded:
            msg = (
                f"Bag {bag.label!r} looks damaged: topic {topic!r} gave {seen} of the "
                f"{recorded} messages its index records; re-copy the file or reindex it."
            )
            raise ReaderError(msg)


def _indexed_mcap_messages(
    bag: Bag, connections: Sequence[Connection]
) -> list[tuple[Connection, int, bytes]] | None:
    """Read MCAP messages through the file's index, or return None when it cannot serve."""
    if bag.storage_format is not BagFormat.ROSBAG2_MCAP:
        return None
    files: list[Path | RemoteFile] = []
    for reader in bag.reader.readers:
        if not isinstance(reader, Rosbag2Reader) or reader.compression_mode:
            return None
        if isinstance(reader.path, RemoteFile):  # read by position: its index, then messages
            files.append(reader.path)
            continue
        rpath = Path(str(reader.path))
        files.extend(sorted(rpath.glob("*.mcap")) if rpath.is_dir() else [rpath])
    keys = [(c.topic, c.msgtype) for c in connections]
    out: list[tuple[Connection, int, bytes]] = []
    for file in files:
        messages = read_indexed_messages(file, keys)
        if messages is None:
            return None
        out.extend((connections[i], log_time, data) for log_time, i, data in messages)
    if len(files) > 1:
        out.sort(key=lambda x: x[1])
    return out


def deserialize(bag: Bag, raw: bytes, msgtype: str) -> object:
    """Deserialize one message, turning rosbags errors into ReaderError."""
    with converted(bag.label):
        return bag.reader.deserialize(raw, msgtype)


def listing(items: Sequence[str]) -> str:
    """Join names with commas, cut after the first forty."""
    if len(items) <= _MAX_LISTED:
        return ", ".join(items)
    return f"{', '.join(items[:_MAX_LISTED])} and {len(items) - _MAX_LISTED} more"
