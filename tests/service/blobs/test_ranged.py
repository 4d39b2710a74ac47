"""Ranged reads of objects in a real SeaweedFS: seek anywhere, fetch only what is read.

The bytes fetched are counted where the client receives them (a wrapper of the real client's
HTTP session reads each GET's ``Content-Length`` as the store answered it:
:class:`tests.service.blobs.conftest.GetCounter`), not by the reader's own counters alone.
"""

from __future__ import annotations

import io
import os
import zipfile
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

import tests.bagfactory as bf
from loceval.readers import _mcap
from loceval.readers._mcap import read_indexed_messages
from service.blobs.ranged import RangedFile
from tests.service.blobs.conftest import GetCounter, SeaweedFS

MIB = 1 << 20


@pytest.fixture
def counted(seaweedfs: SeaweedFS) -> GetCounter:
    """A real S3 client whose GETs are counted as the store answered them."""
    return GetCounter(seaweedfs.client())


def test_seeks_and_reads_like_a_local_file_in_bounded_memory(
    counted: GetCounter, bucket: str, rng: np.random.Generator
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
    counted: GetCounter, bucket: str, rng: np.random.Generator, tmp_path: Path
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


def _camera_bag(rng: np.random.Generator, tmp_path: Path) -> Path:
    """An MCAP file of 200 tf messages at 20 Hz and a 256x256 RGB image at each (40 MB)."""
    poses = bf.random_poses(rng, 200, dt_ns=50_000_000)
    records = bf.tf_records(bf.link_transforms("map", "base_link", poses))
    records += [
        bf.image_record("/camera/image", int(poses.stamps_ns[i]), size=256) for i in range(200)
    ]
    return next(bf.write_bag(tmp_path / "cam", records, fmt="mcap").glob("*.mcap"))


def test_an_mcap_index_reads_only_the_wanted_messages(
    counted: GetCounter, bucket: str, rng: np.random.Generator, tmp_path: Path
) -> None:
    """tf of a camera bag read through its MCAP index over ranged requests: the same messages
    as rosbags reads from the local file, for a small part of the file's bytes."""
    mcap = _camera_bag(rng, tmp_path)
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
    # Each chunk's tf index is one GET, and each run of tf between two images another (the
    # summary takes 3): 237 GETs here, one after another, before batched reads. The index
    # GET also brings the next chunk's first tf messages, so those runs cost nothing (204).
    fd = os.open(mcap, os.O_RDONLY)
    try:
        chunks = len(_mcap._read_summary(_mcap._LocalFile(fd))[2])
    finally:
        os.close(fd)
    assert counted.calls < 3 + chunks + 200, (counted.calls, chunks)


def test_many_reads_at_once_give_the_bytes_of_each(
    counted: GetCounter, bucket: str, rng: np.random.Generator
) -> None:
    """pread_many: each read's bytes in order (short at the end), one GET each, none kept."""
    data = rng.bytes(3 * MIB + 77)
    counted.client.put_object(Bucket=bucket, Key="blob", Body=data)
    ranged = RangedFile(counted.client, bucket, "blob")
    reads = [(int(rng.integers(1, 70_000)), int(rng.integers(0, len(data)))) for _ in range(100)]
    reads += [(500, len(data) - 10), (10, len(data) + 5)]  # past the end: short, then empty
    got = ranged.pread_many(reads)
    assert got == [data[offset : offset + size] for size, offset in reads]
    expected = sum(min(size, max(len(data) - offset, 0)) for size, offset in reads)
    assert counted.bytes == ranged.fetched_bytes == expected
    assert counted.calls == ranged.requests == len(reads) - 1  # nothing asked past the end
    assert ranged.cached_bytes == 0


def test_a_read_of_an_object_gone_meanwhile_is_a_503(counted: GetCounter, bucket: str) -> None:
    """The object deleted after opening: the read fails as the store's outage does (503)."""
    from service.errors import ServiceUnavailableError

    counted.client.put_object(Bucket=bucket, Key="blob", Body=b"x" * 10_000)
    ranged = RangedFile(counted.client, bucket, "blob")
    counted.client.delete_object(Bucket=bucket, Key="blob")
    with pytest.raises(ServiceUnavailableError, match=r"ranged GET: 404"):
        ranged.pread(10, 0)


def test_an_mcap_summary_is_read_in_a_few_requests(
    counted: GetCounter, bucket: str, rng: np.random.Generator, tmp_path: Path
) -> None:
    """Opening a camera bag in a bucket reads its summary in a few GETs, not one per record.

    rosbags checks each summary record's length against the file's size; asked by seeking
    to the end, the buffered reader dropped its buffer and every record cost a new GET
    whenever a record ran past the last one fetched.
    """
    from loceval.readers.rosbag.bagfile import open_bag
    from service.blobs.ranged import ObjectFile

    mcap = _camera_bag(rng, tmp_path)
    counted.client.upload_file(str(mcap), bucket, "cam.mcap")
    with open_bag(ObjectFile(counted.client, bucket, "cam.mcap", name="cam.mcap")) as bag:
        assert {c.topic for c in bag.reader.connections} == {"/tf", "/camera/image"}
    # three GETs: the file's start, its footer, its summary (five before the fix here; the
    # summary of the 2 GB bag of benchmarks.object_store, 1,083 chunks, took 777)
    assert counted.calls <= 3, counted.calls
