"""Safe extraction of a zipped bag (a ROS 2 bag directory, an MCAP file or ROS 1 bags).

Uploads of ROS 2 bags arrive as zip files because a bag is a directory. A zip is untrusted
input, so extraction refuses members that would land outside the target directory
(absolute paths, ``..``), symbolic links, encrypted members, more than ``max_total_bytes``
of content, and members (or archives) that inflate by more than ``max_ratio`` (zip bombs).
Sizes are enforced on the bytes actually written, not on the sizes the archive declares.
"""

from __future__ import annotations

import stat
import tempfile
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path, PurePosixPath
from typing import IO

from loceval.errors import LocevalError, ReaderError

__all__ = [
    "DEFAULT_MAX_RATIO",
    "DEFAULT_MAX_TOTAL_BYTES",
    "extract_zip",
    "extracted_bag",
    "find_bag",
    "zip_contains_bag",
]

DEFAULT_MAX_TOTAL_BYTES = 20 * 1024**3
"""Largest total size of the extracted files: 20 GiB."""
DEFAULT_MAX_RATIO = 200.0
"""Largest uncompressed/compressed size ratio of a member (deflate bombs reach ~1000)."""
MAX_MEMBERS = 10_000
"""A bag folder holds a metadata.yaml and its split files; far more members is no bag."""
_RATIO_MIN_BYTES = 1024**2
"""Members smaller than this are not ratio-checked (tiny files compress arbitrarily well)."""
_COPY_BLOCK = 1024**2
_MAX_LISTED = 30


def extract_zip(
    zip_path: Path,
    target_dir: Path,
    *,
    max_total_bytes: int = DEFAULT_MAX_TOTAL_BYTES,
    max_ratio: float = DEFAULT_MAX_RATIO,
) -> list[Path]:
    """Extract a zip file safely into ``target_dir``.

    Args:
        zip_path: the zip file.
        target_dir: an existing directory to extract into.
        max_total_bytes: largest total size of the extracted files, in bytes.
        max_ratio: largest uncompressed/compressed ratio of a member larger than 1 MiB
            and of the whole archive.

    Returns:
        The extracted files (not directories), in archive order.

    Raises:
        ReaderError: the file is not a zip, or a member is unsafe (absolute path, ``..``
            escape, symlink, encrypted), or the limits are exceeded.
    """
    root = target_dir.resolve()
    try:
        archive = zipfile.ZipFile(zip_path)
    except FileNotFoundError as err:
        msg = f"Zip file {str(zip_path)!r} does not exist; check the path."
        raise ReaderError(msg) from err
    except (zipfile.BadZipFile, OSError) as err:
        msg = f"File {zip_path.name!r} is not a readable zip archive ({err}); re-create the zip."
        raise ReaderError(msg) from err
    with archive:
        members = archive.infolist()
        if len(members) > MAX_MEMBERS:
            msg = (
                f"Zip file {zip_path.name!r} holds {len(members):,} members, more than the "
                f"{MAX_MEMBERS:,} a bag needs; zip only the bag folder."
            )
            raise ReaderError(msg)
        _check_unique(members, zip_path)
        for info in members:
            _check_member(info, root, zip_path, max_ratio=max_ratio)
        declared = sum(info.file_size for info in members)
        compressed = sum(info.compress_size for info in members)
        if declared > max_total_bytes:
            msg = (
                f"Zip file {zip_path.name!r} would extract to {declared} bytes, more than "
                f"the limit of {max_total_bytes}; upload a smaller bag or raise the limit."
            )
            raise ReaderError(msg)
        if declared > _RATIO_MIN_BYTES and declared > max_ratio * max(compressed, 1):
            msg = (
                f"Zip file {zip_path.name!r} inflates {declared / max(compressed, 1):.0f}-fold, "
                f"more than the limit of {max_ratio:g} (a zip bomb?); upload the bag unzipped "
                "or zip it without nested archives."
            )
            raise ReaderError(msg)
        written = 0
        files: list[Path] = []
        for info in members:
            dest = _destination(info.filename, root, zip_path)
            if info.is_dir():
                dest.mkdir(parents=True, exist_ok=True)
                continue
            dest.parent.mkdir(parents=True, exist_ok=True)
            written = _copy_member(
                archive, info, dest, zip_path, written=written, max_total_bytes=max_total_bytes
            )
            files.append(dest)
    return files


def find_bag(directory: Path, *, what: str) -> list[Path]:
    """Find the bag in an extracted archive.

    A ROS 2 bag directory (the folder of exactly one ``metadata.yaml``) wins; else exactly
    one ``.mcap`` or ``.db3`` file; else every ``.bag`` file (a split ROS 1 recording,
    sorted by name).

    Args:
        directory: the extraction directory.
        what: the archive's name, for messages.

    Returns:
        The paths to pass to the bag reader.

    Raises:
        ReaderError: no bag, or several candidate bags; the message lists the contents.
    """
    files = sorted(p for p in directory.rglob("*") if p.is_file())
    metadata = [p.parent for p in files if p.name == "metadata.yaml"]
    # Storage files inside a bag directory belong to it; only loose ones are bags of their own.
    single = [
        p
        for p in files
        if p.suffix in {".mcap", ".db3"} and not any(p.is_relative_to(m) for m in metadata)
    ]
    ros1 = [p for p in files if p.suffix == ".bag"]
    if len(metadata) == 1 and not single and not ros1:
        return metadata
    if not metadata and len(single) == 1 and not ros1:
        return single
    if not metadata and not single and ros1:
        return ros1
    contents = _listing([str(p.relative_to(directory)) for p in files]) or "nothing"
    if metadata or single:
        msg = (
            f"Zip file {what!r} holds several bags ({contents}); zip one bag directory or "
            "one bag file per upload."
        )
        raise ReaderError(msg)
    msg = (
        f"Zip file {what!r} holds no bag (no metadata.yaml, .mcap, .db3 or .bag file); it "
        f"holds: {contents}; zip the ROS 2 bag directory itself."
    )
    raise ReaderError(msg)


@contextmanager
def extracted_bag(
    zip_path: Path,
    *,
    target_dir: Path | None = None,
    max_total_bytes: int = DEFAULT_MAX_TOTAL_BYTES,
    max_ratio: float = DEFAULT_MAX_RATIO,
) -> Iterator[list[Path]]:
    """Extract a zipped bag and yield the paths to read; clean up a temporary directory.

    Args:
        zip_path: the zip file.
        target_dir: where to extract; None for a temporary directory that is removed on
            exit (a caller-given directory is left in place).
        max_total_bytes: see :func:`extract_zip`.
        max_ratio: see :func:`extract_zip`.

    Yields:
        The bag paths (see :func:`find_bag`).

    Raises:
        ReaderError: see :func:`extract_zip` and :func:`find_bag`. Any loceval error raised
            while the bag is read from the temporary folder names the files in it as
            members of the zip (``rec.zip:bag/metadata.yaml``), never by the folder.
    """
    if target_dir is not None:
        target_dir.mkdir(parents=True, exist_ok=True)
        extract_zip(zip_path, target_dir, max_total_bytes=max_total_bytes, max_ratio=max_ratio)
        yield find_bag(target_dir, what=zip_path.name)
        return
    with tempfile.TemporaryDirectory(prefix="loceval-zip-") as tmp:
        try:
            extract_zip(zip_path, Path(tmp), max_total_bytes=max_total_bytes, max_ratio=max_ratio)
            yield find_bag(Path(tmp), what=zip_path.name)
        except LocevalError as err:
            # Whatever failed inside (rosbags, the YAML, sqlite) names extracted files by
            # their temporary path: name them as members of the zip instead.
            err.args = (_as_members(str(err), Path(tmp), zip_path.name), *err.args[1:])
            raise


def zip_contains_bag(zip_path: Path) -> bool:
    """Whether a zip's member names include a bag (without extracting anything)."""
    try:
        with zipfile.ZipFile(zip_path) as archive:
            names = archive.namelist()
    except (zipfile.BadZipFile, OSError):
        return False
    suffixes = {".mcap", ".db3", ".bag"}
    return any(
        PurePosixPath(n).name == "metadata.yaml" or PurePosixPath(n).suffix in suffixes
        for n in names
    )


def _check_unique(members: list[zipfile.ZipInfo], zip_path: Path) -> None:
    """Refuse a zip that holds a member name twice (which copy would be the bag's?)."""
    names = [PurePosixPath(i.filename.replace("\\", "/")).as_posix() for i in members]
    seen: set[str] = set()
    for name in names:
        if name in seen:
            msg = (
                f"Zip file {zip_path.name!r} holds the member {name!r} twice; re-create the "
                "zip from the bag folder."
            )
            raise ReaderError(msg)
        seen.add(name)


def _check_member(info: zipfile.ZipInfo, root: Path, zip_path: Path, *, max_ratio: float) -> None:
    _destination(info.filename, root, zip_path)
    mode = info.external_attr >> 16
    if stat.S_ISLNK(mode):
        msg = (
            f"Zip file {zip_path.name!r} holds the symbolic link {info.filename!r}, which is "
            "refused; zip the files themselves, not links to them."
        )
        raise ReaderError(msg)
    if info.flag_bits & 0x1:
        msg = (
            f"Zip file {zip_path.name!r} holds the encrypted member {info.filename!r}; upload "
            "an unencrypted zip."
        )
        raise ReaderError(msg)
    if info.file_size > _RATIO_MIN_BYTES and info.file_size > max_ratio * max(
        info.compress_size, 1
    ):
        msg = (
            f"Zip member {info.filename!r} of {zip_path.name!r} inflates "
            f"{info.file_size / max(info.compress_size, 1):.0f}-fold, more than the limit of "
            f"{max_ratio:g} (a zip bomb?); upload the bag unzipped."
        )
        raise ReaderError(msg)


def _destination(name: str, root: Path, zip_path: Path) -> Path:
    """Return where a member goes, refusing names that leave ``root``."""
    # Zip names use '/', but archives made on Windows may hold '\'; treat both as separators.
    parts = PurePosixPath(name.replace("\\", "/"))
    drive_like = bool(parts.parts) and parts.parts[0].endswith(":")
    if parts.is_absolute() or drive_like or ".." in parts.parts:
        msg = (
            f"Zip file {zip_path.name!r} holds the member {name!r}, whose path leaves the "
            "extraction folder; re-create the zip with relative paths."
        )
        raise ReaderError(msg)
    dest = (root / parts).resolve()
    if not dest.is_relative_to(root):
        msg = (
            f"Zip file {zip_path.name!r} holds the member {name!r}, whose path leaves the "
            "extraction folder; re-create the zip with relative paths."
        )
        raise ReaderError(msg)
    return dest


def _copy_member(
    archive: zipfile.ZipFile,
    info: zipfile.ZipInfo,
    dest: Path,
    zip_path: Path,
    *,
    written: int,
    max_total_bytes: int,
) -> int:
    """Stream one member to ``dest``, enforcing the limits on the bytes really written."""
    try:
        with archive.open(info) as src, dest.open("xb") as out:
            copied = _copy_limited(src, out, limit=min(info.file_size, max_total_bytes - written))
    except (zipfile.BadZipFile, EOFError, OSError, ValueError) as err:
        dest.unlink(missing_ok=True)
        msg = (
            f"Zip member {info.filename!r} of {zip_path.name!r} cannot be extracted ({err}); "
            "re-create the zip."
        )
        raise ReaderError(msg) from err
    if copied is None:
        dest.unlink(missing_ok=True)
        msg = (
            f"Zip member {info.filename!r} of {zip_path.name!r} inflates beyond its declared "
            "size or the total size limit; upload the bag unzipped."
        )
        raise ReaderError(msg)
    return written + copied


def _copy_limited(src: IO[bytes], out: IO[bytes], *, limit: int) -> int | None:
    """Copy at most ``limit`` bytes; return the count, or None if there was more."""
    copied = 0
    while block := src.read(_COPY_BLOCK):
        copied += len(block)
        if copied > limit:
            return None
        out.write(block)
    return copied


def _as_members(message: str, folder: Path, zip_name: str) -> str:
    """Write paths inside the extraction ``folder`` as ``ZIP:MEMBER`` (``rec.zip:bag/x``)."""
    for form in sorted({str(folder), str(folder.resolve())}, key=len, reverse=True):
        message = message.replace(f"{form}/", f"{zip_name}:").replace(form, zip_name)
    return message


def _listing(names: list[str]) -> str:
    if len(names) <= _MAX_LISTED:
        return ", ".join(names)
    return f"{', '.join(names[:_MAX_LISTED])} and {len(names) - _MAX_LISTED} more"
