"""An MCAP file's small messages held while its bytes stream past (loceval.readers.rosbag.held).

The reference is the index reader (:func:`loceval.readers._mcap.read_indexed_messages`) on
the same file: what a scan holds must be exactly what it reads, in the same order, however
the bytes are cut into pieces.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
import pytest

from loceval.inspection.bag import inspect_bag_file
from loceval.readers._mcap import read_indexed_messages
from loceval.readers.rosbag import HeldFile, HeldMessages, McapScan
from loceval.readers.rosbag.held import HELD_MESSAGE_BYTES
from tests import bagfactory as bf

NS = bf.NS
T0 = bf.T0_NS
WANTED = [("/tf", bf.TF), ("/pose", bf.POSE), ("/tf_static", bf.TF)]


class CountingFile:
    """A local file as a RemoteFile that counts the bytes read by position (the index reader)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.name = path.name
        self.suffix = path.suffix
        self.size = path.stat().st_size
        self.pread_bytes = 0

    def exists(self) -> bool:
        return True

    def is_dir(self) -> bool:
        return False

    def open(self, mode: str = "rb") -> BinaryIO:
        assert mode == "rb"
        return self.path.open("rb")

    def pread(self, size: int, offset: int) -> bytes:
        with self.path.open("rb") as fh:
            fh.seek(offset)
            data = fh.read(size)
        self.pread_bytes += len(data)
        return data


def camera_bag(tmp_path: Path, rng: np.random.Generator, **kwargs: str) -> Path:
    """An MCAP bag: tf at 60 Hz, a pose topic, a static link and 100x100 images at 15 Hz."""
    base = bf.random_poses(rng, 240, dt_ns=16_666_667)
    pose = bf.random_poses(rng, 80, dt_ns=50_000_000)
    records = [
        *bf.tf_records(bf.link_transforms("odom", "base_link", base)),
        *bf.pose_records("/pose", bf.POSE, pose),
        *bf.tf_records(
            [bf.Tf(T0, "base_link", "camera", (0.1, 0, 0.2), (0, 0, 0, 1))], topic="/tf_static"
        ),
        *(bf.image_record("/camera", T0 + i * 66_666_667, size=100) for i in range(60)),
    ]
    directory = bf.write_bag(bf.bag_path(tmp_path, "mcap"), records, fmt="mcap", **kwargs)
    return next(directory.glob("*.mcap"))


def pieces(data: bytes, seed: int, largest: int) -> Iterator[bytes]:
    """Cut ``data`` into pieces of 1 to ``largest`` bytes."""
    steps = np.random.default_rng(seed).integers(1, largest + 1, size=len(data) + 1)
    ends = np.cumsum(steps)
    start = 0
    for end in ends[: int(np.searchsorted(ends, len(data))) + 1].tolist():
        yield data[start:end]
        start = end


def scanned(data: bytes, *, largest: int = 1 << 16, seed: int = 7, **kwargs: Any) -> McapScan:
    scan = McapScan(**kwargs)
    for piece in pieces(data, seed, largest):
        scan.feed(piece)
    return scan


@pytest.mark.parametrize(
    ("largest", "seed"), [(1, 0), (7, 1), (300, 2), (1 << 16, 3), (1 << 22, 4)]
)
def test_a_scan_holds_what_the_index_reads_however_the_bytes_are_cut(tmp_path, rng, largest, seed):
    """Pieces of one byte, a few bytes, or more than the file: the same messages, in order."""
    mcap = camera_bag(tmp_path, rng)
    expected = read_indexed_messages(mcap, WANTED)
    assert expected is not None
    assert len(expected) == 240 + 80 + 1
    held = scanned(mcap.read_bytes(), largest=largest, seed=seed).finish()
    assert held is not None
    assert held.messages(WANTED) == expected
    for key in WANTED:  # one channel at a time, as the readers ask
        assert held.messages([key]) == read_indexed_messages(mcap, [key])
    assert held.messages([("/camera", bf.IMAGE)]) is None  # no inspection reads images
    assert held.messages([("/nothing", bf.TF)]) == []
    everything = scanned(mcap.read_bytes(), keeps=lambda _: True).finish()
    assert everything is not None
    cameras = read_indexed_messages(mcap, [("/camera", bf.IMAGE)])
    assert everything.messages([("/camera", bf.IMAGE)]) == cameras
    assert cameras is not None
    assert len(cameras) == 60


def test_inspecting_a_held_file_reads_no_message_again(tmp_path, rng):
    """The inspection equals the local one and reads no message back from the store."""
    mcap = camera_bag(tmp_path, rng)
    held = scanned(mcap.read_bytes()).finish()
    assert held is not None
    remote = CountingFile(mcap)
    got = inspect_bag_file(HeldFile(remote, held)).to_dict()
    expected = inspect_bag_file(mcap).to_dict()
    del got["path"], expected["path"]
    assert got == expected
    assert remote.pread_bytes == 0
    # without what was held, the index reader fetches the tf and pose messages
    again = CountingFile(mcap)
    assert inspect_bag_file(again).to_dict()["sources"] == expected["sources"]
    assert again.pread_bytes > 0


def test_a_channel_past_the_limit_is_let_go_and_read_from_the_file(tmp_path, rng):
    """The channel holding most goes when the limit is passed; asking for it gives None."""
    mcap = camera_bag(tmp_path, rng)
    held = scanned(mcap.read_bytes(), keeps=lambda _: True, held_bytes=200_000).finish()
    assert held is not None
    assert held.messages([("/camera", bf.IMAGE)]) is None
    assert held.messages(WANTED) == read_indexed_messages(mcap, WANTED)
    # an inspection through it still reads the image-free answer, and a reader asking for
    # the camera reads it where it lies
    remote = CountingFile(mcap)
    file = HeldFile(remote, held)
    cameras = read_indexed_messages(file, [("/camera", bf.IMAGE)])
    assert cameras == read_indexed_messages(mcap, [("/camera", bf.IMAGE)])
    assert remote.pread_bytes > 60 * 30_000


def test_a_message_over_the_per_message_limit_lets_its_channel_go(tmp_path, rng):
    """A channel with one message larger than HELD_MESSAGE_BYTES is never held."""
    side = int((HELD_MESSAGE_BYTES / 3) ** 0.5) + 2
    records = [
        *bf.tf_records(bf.link_transforms("odom", "base_link", bf.random_poses(rng, 20, dt_ns=NS))),
        bf.image_record("/camera", T0 + 5 * NS, size=10),
        bf.image_record("/camera", T0 + 6 * NS, size=side),
    ]
    directory = bf.write_bag(bf.bag_path(tmp_path, "mcap"), records, fmt="mcap")
    mcap = next(directory.glob("*.mcap"))
    held = scanned(mcap.read_bytes(), keeps=lambda _: True).finish()
    assert held is not None
    assert held.messages([("/camera", bf.IMAGE)]) is None
    assert held.messages([("/tf", bf.TF)]) == read_indexed_messages(mcap, [("/tf", bf.TF)])


def test_what_the_index_cannot_serve_is_not_held(tmp_path, rng):
    """Compressed chunks, a cut file, bytes past the end, another format: None, no error."""
    compressed = camera_bag(tmp_path / "zstd", rng, compression="storage")
    assert read_indexed_messages(compressed, WANTED) is None
    assert scanned(compressed.read_bytes()).finish() is None
    data = camera_bag(tmp_path / "plain", rng).read_bytes()
    assert scanned(data).finish() is not None
    for cut in (0, 5, 8, 9, len(data) // 2, len(data) - 9, len(data) - 1):
        assert scanned(data[:cut]).finish() is None, cut
    assert scanned(data + b"\0").finish() is None
    ros1 = bf.write_bag(
        tmp_path / "rec.bag",
        bf.tf_records(bf.link_transforms("odom", "base_link", bf.random_poses(rng, 5, dt_ns=NS))),
        fmt="rosbag1",
    )
    assert scanned(ros1.read_bytes()).finish() is None


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


@pytest.mark.parametrize(
    "tail",
    [
        struct.pack("<BQ", 0x03, 1 << 60),  # a schema of an exabyte
        struct.pack("<BQ", 0x06, 1 << 62) + struct.pack("<QQQII", 0, 0, 0, 0, 1 << 31),
        _record(0x05, struct.pack("<HIQQ", 1, 0, 0, 0) + b"loose"),  # a message outside chunks
        _record(0x04, struct.pack("<HH", 1, 1) + struct.pack("<I", 1 << 30)),  # a cut string
    ],
    ids=["huge-schema", "huge-compression-name", "loose-message", "bad-string"],
)
def test_hostile_records_give_up_without_holding_or_raising(tail):
    """Lengths of exabytes, garbled strings: the scan gives up at once and holds nothing."""
    scan = McapScan()
    scan.feed(b"\x89MCAP0\r\n" + _record(0x01, struct.pack("<I", 0) + struct.pack("<I", 0)))
    scan.feed(tail)
    scan.feed(bytes(1 << 20))  # whatever follows is not looked at
    assert scan.finish() is None


def test_held_messages_follow_channels_by_topic_and_type():
    """Channels are matched by topic and schema name; a non-CDR channel is not served."""
    held = HeldMessages(
        {1: bf.TF, 2: bf.POSE},
        {1: ("/tf", 1, "cdr"), 2: ("/pose", 2, "cdr"), 3: ("/tf", 1, "cdr"), 4: ("/j", 2, "json")},
        {1: [(5, 0, b"a"), (9, 3, b"d")], 3: [(5, 1, b"b")], 2: [(1, 2, b"c")]},
        set(),
    )
    assert held.messages([("/tf", bf.TF)]) == [(5, 0, b"a"), (5, 0, b"b"), (9, 0, b"d")]
    wanted: Sequence[tuple[str, str]] = [("/pose", bf.POSE), ("/tf", bf.TF)]
    assert held.messages(wanted) == [(1, 0, b"c"), (5, 1, b"a"), (5, 1, b"b"), (9, 1, b"d")]
    assert held.messages([("/j", bf.POSE)]) is None
    assert held.messages([("/pose", bf.TF)]) == []


def test_held_messages_read_back_from_their_bytes_as_they_were(tmp_path, rng):
    """to_bytes then from_bytes: every channel's messages, the dropped ones still dropped."""
    mcap = camera_bag(tmp_path, rng)
    held = scanned(mcap.read_bytes()).finish()
    assert held is not None
    back = HeldMessages.from_bytes(held.to_bytes())
    assert back.schemas == held.schemas
    assert back.channels == held.channels
    for wanted in (WANTED, *([key] for key in WANTED)):
        assert back.messages(wanted) == held.messages(wanted) == read_indexed_messages(mcap, wanted)
    assert back.messages([("/camera", bf.IMAGE)]) is None  # let go while scanning: still so
    empty = HeldMessages({}, {}, {}, set())
    assert HeldMessages.from_bytes(empty.to_bytes()).messages(WANTED) == []


@pytest.mark.parametrize(
    "damage",
    [
        lambda b: b[:-1],  # cut short
        lambda b: b + b"x",  # bytes past the end
        lambda b: b"LOCEVAL-HELD-2\n" + b[15:],  # another version
        lambda b: b[:15] + struct.pack("<I", 3) + b"{x}" + b[19:],  # a head that is no JSON
        lambda b: b[:10],
    ],
)
def test_damaged_held_bytes_are_refused(tmp_path, rng, damage):
    """Damaged or foreign bytes raise ValueError (the reader then reads the file's index)."""
    held = scanned(camera_bag(tmp_path, rng).read_bytes()).finish()
    assert held is not None
    with pytest.raises(ValueError, match="held MCAP messages"):
        HeldMessages.from_bytes(damage(held.to_bytes()))
