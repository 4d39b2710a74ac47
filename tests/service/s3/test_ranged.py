"""Ranged reads of objects in a real SeaweedFS: seek anywhere, fetch only what is read.

The bytes fetched are counted where boto3 receives them (an ``after-call`` hook on the real
client reads each GetObject's ``Content-Length`` as the store answered it), not by the
reader's own counters alone.
"""

from __future__ import annotations

import io
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

import tests.bagfactory as bf
from loceval.readers._mcap import read_indexed_messages
from service.blobs.ranged import RangedFile
from tests.service.s3.conftest import SeaweedFS

MIB = 1 << 20


class _Counted:
    """A real S3 client whose GetObject answers are counted as the store sent them."""

    def __init__(self, server: SeaweedFS) -> None:
        self.client = server.client()
        self.bytes = 0
        self.calls = 0
        self.client.meta.events.register("after-call.s3.GetObject", self._count)

    def _count(self, parsed: dict[str, Any], **_: Any) -> None:
        self.calls += 1
        self.bytes += int(parsed.get("ContentLength", 0))


@pytest.fixture
def counted(seaweedfs: SeaweedFS) -> _Counted:
    return _Counted(seaweedfs)


def test_seeks_and_reads_like_a_local_file_in_bounded_memory(
    counted: _Counted, bucket: str, rng: np.random.Generator
) -> None:
    """Random seeks and reads give the object's bytes; at most max_cached bytes are kept."""
    data = rng.bytes(12 * MIB + 12345)
    counted.client.put_object(Bucket=bucket, Key="blob", Body=data)
    ranged = RangedFile(counted.client, bucket, "blob", max_ahead=MIB, max_cached=2 * MIB)
    assert ranged.size == len(data)
    buffered = io.BufferedReader(ranged, buffer_size=4096)
    for offset, size in [(0, 10), (len(data) - 7, 100), (MIB - 3, 9), (3 << 20, 2 << 20)]:
        buffered.seek(offset)
        assert buffered.read(size) == data[offset : offset + size]
    assert ranged.seek(-5, io.SEEK_END) == len(data) - 5
    assert ranged.read() == data[-5:]
    assert ranged.read(10) == b""  # at the end
    assert ranged.pread(4, 2) == data[2:6]
    assert ranged.cached_bytes <= 2 * MIB
    assert counted.bytes == ranged.fetched_bytes < len(data)  # never the whole object
    with pytest.raises(OSError, match="negative"):
        ranged.seek(-1)


def test_a_zip_central_directory_is_read_without_the_members(
    counted: _Counted, bucket: str, rng: np.random.Generator, tmp_path: Path
) -> None:
    """A 24 MB zip: listing it and reading its small member fetch well under a tenth of it."""
    archive = tmp_path / "bag.zip"
    with zipfile.ZipFile(archive, "w", compression=zipfile.ZIP_STORED) as zipped:
        zipped.writestr("run/metadata.yaml", "rosbag2_bagfile_information: {}\n")
        zipped.writestr("run/run_0.mcap", rng.bytes(24 << 20))
    counted.client.upload_file(str(archive), bucket, "bag.zip")
    with zipfile.ZipFile(RangedFile(counted.client, bucket, "bag.zip")) as remote:
        assert remote.namelist() == ["run/metadata.yaml", "run/run_0.mcap"]
        assert remote.read("run/metadata.yaml").startswith(b"rosbag2_bagfile_information")
    assert 0 < counted.bytes < archive.stat().st_size / 10


def test_an_mcap_index_reads_only_the_wanted_messages(
    counted: _Counted, bucket: str, rng: np.random.Generator, tmp_path: Path
) -> None:
    """tf of a camera bag read through its MCAP index over ranged requests: the same messages
    as rosbags reads from the local file, for a small part of the file's bytes."""
    poses = bf.random_poses(rng, 200, dt_ns=50_000_000)
    records = bf.tf_records(bf.link_transforms("map", "base_link", poses))
    records += [
        bf.image_record("/camera/image", int(poses.stamps_ns[i]), size=256) for i in range(200)
    ]
    bag = bf.write_bag(tmp_path / "cam", records, fmt="mcap")
    mcap = next(bag.glob("*.mcap"))
    counted.client.upload_file(str(mcap), bucket, "cam.mcap")
    ranged = RangedFile(counted.client, bucket, "cam.mcap")
    indexed = read_indexed_messages(ranged, [("/tf", bf.TF)])
    assert indexed is not None
    with AnyReader([mcap]) as reader:
        conns = [c for c in reader.connections if c.topic == "/tf"]
        expected = [(t, bytes(raw)) for _, t, raw in reader.messages(conns)]
    assert [(t, bytes(d)) for t, _, d in indexed] == expected
    size = mcap.stat().st_size
    assert size > 30 << 20  # 200 images of 256x256 rgb8
    assert counted.bytes == ranged.fetched_bytes < size / 10
