"""Reading occupancy grid maps: map_server's YAML and image, a zip of both, a bag topic.

map_server's pair is a YAML file (``image``, ``resolution``, ``origin: [x, y, yaw]``,
``negate``, ``occupied_thresh``, ``free_thresh``) and its PGM (binary P5 or text P2) or
PNG image; the image's top row is the map's far edge (largest y), so it is flipped into
the grid's layout. A pixel's occupancy is ``(255 - p) / 255`` (``p / 255`` with
``negate: 1``): occupied above ``occupied_thresh``, free below ``free_thresh``, unknown
between, as map_server's trinary mode reads it.

The declared size (the PGM header's, the PNG's, the message's width and height) is checked
against :data:`~loceval.maps.grid.MAX_MAP_CELLS` before the cells are read, and the data
must match it: a truncated or mislabelled image is refused with the reason.
"""

from __future__ import annotations

import io
import math
import re
import warnings
import zipfile
from collections.abc import Iterator
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING, Final

import numpy as np
from numpy.typing import NDArray

from loceval.errors import InputError, ReaderError
from loceval.maps.grid import FREE, MAX_MAP_CELLS, OCCUPIED, UNKNOWN, OccupancyGrid, check_map_size

if TYPE_CHECKING:
    from loceval.readers.rosbag.grid import GridMessage

__all__ = [
    "MAP_SUFFIXES",
    "grid_from_image",
    "grid_from_message",
    "iter_bag_maps",
    "read_bag_map",
    "read_map",
    "read_map_yaml",
    "read_map_zip",
    "split_bag_source",
]

MAP_SUFFIXES: Final = (".yaml", ".yml", ".zip")
"""Map files read without a topic: map_server's YAML, or a zip holding it and its image."""
_HEADER_BYTES: Final = 4096
_PGM_HEADER: Final = re.compile(rb"^(P[25])(?:\s+|#[^\n]*\n)*?(\d+)(?:\s+|#[^\n]*\n)+(\d+)")
_OCCUPIED_PCT: Final = 65
_FREE_PCT: Final = 19.6
_MAX_IMAGE_BYTES: Final = 2 * MAX_MAP_CELLS + _HEADER_BYTES
"""Most bytes of a map image read (16-bit PGM at the largest size)."""


def read_map(source: str) -> OccupancyGrid:
    """Read a map: ``map.yaml`` (beside its image), ``map.zip`` or ``BAG@TOPIC``.

    Args:
        source: the map's YAML, a zip holding the YAML and its image, or a bag and the
            topic of its ``nav_msgs/msg/OccupancyGrid`` messages (the last one is read).

    Raises:
        InputError: the source is none of these, or the map is unreadable or too large.
    """
    path = Path(source)
    if path.suffix.lower() in MAP_SUFFIXES and path.is_file():
        return read_map_zip(path) if path.suffix.lower() == ".zip" else read_map_yaml(path)
    in_bag = split_bag_source(source)
    if in_bag is not None:
        return read_bag_map(*in_bag)
    if not path.exists():
        msg = f"The map {source!r} does not exist; give map.yaml, a zip of it or BAG@TOPIC."
        raise InputError(msg, option="map")
    msg = (
        f"The map {source!r} is not a map_server YAML, a zip of one or BAG@TOPIC; give the "
        "map.yaml beside its image, a zip holding both, or run.bag@/map."
    )
    raise InputError(msg, option="map")


def read_bag_map(path: Path, topic: str) -> OccupancyGrid:
    """Read the last ``nav_msgs/msg/OccupancyGrid`` of a bag topic.

    Cell values are ROS's: -1 unknown, 0-100 the occupancy in percent; occupied from 65,
    free up to 19.6, as map_server saves them (``occupied_thresh: 0.65``,
    ``free_thresh: 0.196``).

    Raises:
        ReaderError: no such topic, no message, data that do not match the declared size.
        InputError: the declared size is over the limit.
    """
    from loceval.readers.rosbag.grid import read_grid_topic  # noqa: PLC0415  (rosbags)

    return grid_from_message(read_grid_topic(path, topic))


def iter_bag_maps(
    path: Path, topic: str, *, limit: int
) -> Iterator[tuple[int, int, OccupancyGrid]]:
    """Yield each ``nav_msgs/msg/OccupancyGrid`` of a bag topic as a grid, in receive order.

    At most ``limit`` messages, evenly spread, the last always among them
    (:func:`loceval.readers.rosbag.grid.kept_indices`); one grid is built at a time.

    Yields:
        ``(index, total, grid)``: the message's position among the topic's ``total``.

    Raises:
        ReaderError: no such topic, no message, data that do not match the declared size.
        InputError: a declared size over the limit.
    """
    from loceval.readers.rosbag.grid import iter_grid_topic  # noqa: PLC0415  (rosbags)

    for index, total, found in iter_grid_topic(path, topic, limit=limit):
        yield index, total, grid_from_message(found)


def grid_from_message(found: GridMessage) -> OccupancyGrid:
    """Turn a ``nav_msgs/msg/OccupancyGrid`` as read into a grid (size checked first).

    Raises:
        ReaderError: data that do not match the declared size.
        InputError: the declared size is over the limit.
    """
    check_map_size(found.width, found.height, where=found.where)
    if found.values.size != found.width * found.height:
        msg = (
            f"{found.where}: the map declares {found.width} x {found.height} cells but holds "
            f"{found.values.size} values; the message is damaged."
        )
        raise ReaderError(msg, option="map")
    values = found.values.reshape(found.height, found.width)
    states = np.full(values.shape, UNKNOWN, dtype=np.int8)
    states[values >= _OCCUPIED_PCT] = OCCUPIED
    states[(values >= 0) & (values <= _FREE_PCT)] = FREE
    return OccupancyGrid(
        states,
        found.resolution_m,
        (float(found.origin_xy[0]), float(found.origin_xy[1])),
        found.origin_yaw_rad,
        source=found.where,
        stamp_ns=found.stamp_ns,
    )


def split_bag_source(source: str) -> tuple[Path, str] | None:
    """Return ``(bag, topic)`` of a ``BAG@TOPIC`` source that is no map file, else None."""
    path = Path(source)
    if path.suffix.lower() in MAP_SUFFIXES and path.is_file():
        return None
    bag, sep, topic = source.rpartition("@")
    return (Path(bag), topic) if sep and bag and topic else None


def read_map_yaml(path: Path) -> OccupancyGrid:
    """Read map_server's YAML and the image it names (beside it).

    Raises:
        ReaderError: the YAML or the image is missing, unreadable or inconsistent.
        InputError: the map is larger than loceval evaluates.
    """
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        msg = f"The map YAML {str(path)!r} cannot be read ({err}); check the file."
        raise ReaderError(msg, option="map") from err
    meta = _parse_yaml(text, str(path))
    image = path.parent / str(meta["image"])
    if not image.is_file():
        msg = (
            f"{path.name}: its image {meta['image']!r} is not beside it; put the image next "
            "to the YAML (or zip both)."
        )
        raise ReaderError(msg, option="map")
    with image.open("rb") as fh:
        data = fh.read(_MAX_IMAGE_BYTES + 1)
    return grid_from_image(data, meta, where=f"{path.name} ({image.name})")


def read_map_zip(path: Path) -> OccupancyGrid:
    """Read a zip holding map_server's YAML and its image.

    Members are read by name, never extracted; at most the largest image's bytes are read.

    Raises:
        ReaderError: not a zip, no or several YAML files, the image missing or inconsistent.
        InputError: the map is larger than loceval evaluates.
    """
    try:
        with zipfile.ZipFile(path) as archive:
            names = [n for n in archive.namelist() if not n.endswith("/")]
            yamls = [n for n in names if n.lower().endswith((".yaml", ".yml"))]
            if len(yamls) != 1:
                msg = (
                    f"The zip {path.name!r} holds {len(yamls)} YAML files; a map zip holds "
                    "exactly one map_server YAML and its image."
                )
                raise ReaderError(msg, option="map")
            with archive.open(yamls[0]) as fh:
                text = fh.read(_HEADER_BYTES * 16).decode("utf-8", errors="replace")
            meta = _parse_yaml(text, f"{path.name}/{yamls[0]}")
            wanted = str(PurePosixPath(yamls[0]).parent / str(meta["image"])).removeprefix("./")
            if wanted not in names:
                msg = (
                    f"The zip {path.name!r} has no {wanted!r}, the image its YAML names; it "
                    f"holds {', '.join(names[:10])}."
                )
                raise ReaderError(msg, option="map")
            with archive.open(wanted) as fh:
                data = fh.read(_MAX_IMAGE_BYTES + 1)
    except (zipfile.BadZipFile, OSError, NotImplementedError, RuntimeError) as err:
        msg = f"The map zip {str(path)!r} cannot be read ({err}); zip the YAML and its image."
        raise ReaderError(msg, option="map") from err
    return grid_from_image(data, meta, where=f"{path.name} ({wanted})")


def grid_from_image(data: bytes, meta: dict[str, object], *, where: str) -> OccupancyGrid:
    """Turn an image's bytes and map_server's metadata into a grid.

    Args:
        data: the PGM or PNG file's bytes.
        meta: the parsed YAML (``_parse_yaml``).
        where: names the map in messages.

    Raises:
        ReaderError: the image is neither PGM nor PNG, or its data do not match its header.
        InputError: the declared size is over the limit.
    """
    if len(data) > _MAX_IMAGE_BYTES:
        msg = f"{where}: the image is over {_MAX_IMAGE_BYTES:,} bytes; crop the map."
        raise InputError(msg, option="map")
    if data[:2] in (b"P5", b"P2"):
        pixels = _read_pgm(data, where=where)
    elif data[:8] == b"\x89PNG\r\n\x1a\n":
        pixels = _read_png(data, where=where)
    else:
        msg = (
            f"{where}: the image is neither a PGM (P5/P2) nor a PNG; save the map with "
            "map_saver or convert the image to PGM."
        )
        raise ReaderError(msg, option="map")
    # one state per grey level (a 256-entry table), so no arithmetic per cell
    occupancy = np.arange(256, dtype=np.float64) / 255.0
    if not meta["negate"]:
        occupancy = 1.0 - occupancy
    table = np.full(256, UNKNOWN, dtype=np.int8)
    table[occupancy > float(str(meta["occupied_thresh"]))] = OCCUPIED
    table[occupancy < float(str(meta["free_thresh"]))] = FREE
    states = table[pixels]
    origin = meta["origin"]
    assert isinstance(origin, tuple)  # noqa: S101  (_parse_yaml makes it one)
    return OccupancyGrid(
        states[::-1],  # the image's top row is the map's far edge
        float(str(meta["resolution"])),
        (origin[0], origin[1]),
        origin[2],
        source=where,
    )


def _parse_yaml(text: str, where: str) -> dict[str, object]:
    """Parse and check map_server's YAML."""
    from ruamel.yaml import YAML  # noqa: PLC0415  (rosbags' own dependency)
    from ruamel.yaml.error import YAMLError  # noqa: PLC0415

    try:
        doc = YAML(typ="safe", pure=True).load(text)
    except YAMLError as err:
        msg = f"{where}: not valid YAML ({err}); check the map's YAML."
        raise ReaderError(msg, option="map") from err
    if not isinstance(doc, dict):
        msg = f"{where}: not a map_server YAML (image, resolution, origin, ...)."
        raise ReaderError(msg, option="map")
    missing = [k for k in ("image", "resolution", "origin") if k not in doc]
    if missing:
        msg = f"{where}: the map YAML lacks {', '.join(missing)}; map_server's YAML names them."
        raise ReaderError(msg, option="map")
    try:
        resolution = float(doc["resolution"])
        origin = tuple(float(v) for v in doc["origin"])
        occupied = float(doc.get("occupied_thresh", 0.65))
        free = float(doc.get("free_thresh", 0.196))
        negate = bool(int(doc.get("negate", 0)))
    except (TypeError, ValueError) as err:
        msg = (
            f"{where}: resolution, origin [x, y, yaw], thresholds and negate must be numbers "
            f"({err})."
        )
        raise ReaderError(msg, option="map") from err
    if len(origin) != 3 or not all(math.isfinite(v) for v in (resolution, *origin)):
        msg = f"{where}: origin must be [x, y, yaw] and finite, got {doc['origin']!r}."
        raise ReaderError(msg, option="map")
    if not resolution > 0 or not 0 <= free <= occupied <= 1:
        msg = (
            f"{where}: resolution {resolution!r} must be positive and 0 <= free_thresh "
            f"({free!r}) <= occupied_thresh ({occupied!r}) <= 1."
        )
        raise ReaderError(msg, option="map")
    return {
        "image": str(doc["image"]),
        "resolution": resolution,
        "origin": origin,
        "occupied_thresh": occupied,
        "free_thresh": free,
        "negate": negate,
    }


def _read_pgm(data: bytes, *, where: str) -> NDArray[np.uint8]:
    """Read a binary (P5) or text (P2) PGM, checking its size before its pixels."""
    head = _PGM_HEADER.match(data[:_HEADER_BYTES])
    rest = (
        re.match(rb"(?:\s+|#[^\n]*\n)+(\d+)\s", data[head.end() : _HEADER_BYTES]) if head else None
    )
    if head is None or rest is None:
        msg = f"{where}: the PGM header (magic, width, height, maxval) is damaged."
        raise ReaderError(msg, option="map")
    width, height, maxval = int(head.group(2)), int(head.group(3)), int(rest.group(1))
    check_map_size(width, height, where=where)
    if not 0 < maxval < 65536:
        msg = f"{where}: the PGM's maxval {maxval} is outside 1..65535."
        raise ReaderError(msg, option="map")
    body = data[head.end() + rest.end() :]
    if head.group(1) == b"P5":
        dtype = np.dtype(">u2") if maxval > 255 else np.dtype(np.uint8)
        need = width * height * dtype.itemsize
        if len(body) < need:
            msg = (
                f"{where}: the PGM header declares {width} x {height} pixels ({need:,} bytes) "
                f"but {len(body):,} bytes follow; the image is truncated or does not belong to "
                "this map."
            )
            raise ReaderError(msg, option="map")
        pixels = np.frombuffer(body[:need], dtype=dtype)
    else:
        try:
            pixels = np.array(body.split(), dtype=np.int64)
        except ValueError as err:
            msg = f"{where}: the text PGM holds something other than numbers."
            raise ReaderError(msg, option="map") from err
        if len(pixels) != width * height:
            msg = (
                f"{where}: the PGM header declares {width} x {height} pixels but "
                f"{len(pixels):,} values follow; the image does not match its header."
            )
            raise ReaderError(msg, option="map")
    grey = np.minimum(pixels.reshape(height, width), maxval)
    if maxval != 255:  # other depths to 0-255 through a table of their levels
        levels = np.rint(np.arange(maxval + 1) * (255.0 / maxval)).astype(np.uint8)
        grey = levels[grey]
    out: NDArray[np.uint8] = grey.astype(np.uint8, copy=False)
    return out


def _read_png(data: bytes, *, where: str) -> NDArray[np.uint8]:
    """Read a PNG as grey levels 0-255, checking its size before decoding."""
    try:
        from PIL import Image  # noqa: PLC0415  (only PNG maps need Pillow)
    except ImportError as err:  # pragma: no cover  (Pillow comes with matplotlib)
        msg = f"{where}: reading PNG maps needs Pillow; install it or convert the map to PGM."
        raise ReaderError(msg, option="map") from err
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)  # sized below
            image = Image.open(io.BytesIO(data))
        with image:
            width, height = image.size
            check_map_size(width, height, where=where)
            grey = np.asarray(image.convert("L"), dtype=np.uint8)
    except (OSError, ValueError, Image.DecompressionBombError) as err:
        msg = f"{where}: the PNG cannot be decoded ({err}); check the image."
        raise ReaderError(msg, option="map") from err
    return grey
