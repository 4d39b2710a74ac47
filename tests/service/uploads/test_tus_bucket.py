"""Resumable uploads into the bucket (SeaweedFS), in-process: parts, tails, expiry.

A 20 MB upload sent in PATCHes of 3 MB crosses the 8 MiB part boundaries mid-request, so
every request reads and writes the tail; the dataset is the file, and an expired or
terminated upload leaves no multipart upload and no object behind.
"""

from __future__ import annotations

import datetime as dt
import hashlib
from collections.abc import Iterator
from pathlib import Path

import pytest

from service.uploads import tus, tus_hashes
from tests.service._api_fixtures import Api, open_api
from tests.service.blobs.conftest import SeaweedFS, object_keys, open_multipart_uploads
from tests.service.uploads.test_tus_protocol import create, offset_of, patch

pytestmark = [pytest.mark.slow]


@pytest.fixture
def api(bucket: str, s3_env: dict[str, str], tmp_path: Path) -> Iterator[Api]:
    """The app with its blobs in a fresh bucket."""
    del s3_env
    with open_api(tmp_path, blob_url=f"s3://{bucket}/site", min_free_bytes=0) as api:
        yield api


@pytest.mark.parametrize("step", [3_000_000, 700_000])
def test_parts_and_tails_make_the_dataset(
    api: Api, large_recording: Path, seaweedfs: SeaweedFS, bucket: str, step: int
) -> None:
    """Each request's bytes past the last whole part are one tail segment, read back once."""
    data = large_recording.read_bytes()
    path = create(api, len(data), filename=large_recording.name, tags="bucket")
    for start in range(0, len(data), step):
        assert offset_of(api, path) == start
        answer = patch(api, path, start, data[start : start + step])
        assert answer.status_code == 204, answer.text
        if start + step < len(data):
            assert open_multipart_uploads(seaweedfs, bucket) == [f"site/tus/{path[-36:]}"]
            # only the segments of the part being filled stay: the others are in parts now
            segments = object_keys(seaweedfs, bucket, f"site/tus/{path[-36:]}.tail/")
            assert len(segments) <= (8 << 20) // step + 1, segments
    state = api.client.get(path, headers=api.headers).json()
    assert state["dataset"]["id"] == answer.headers["loceval-dataset"]
    assert state["dataset"]["sha256"] == hashlib.sha256(data).hexdigest()
    assert state["dataset"]["size_bytes"] == len(data)
    assert open_multipart_uploads(seaweedfs, bucket) == []
    assert object_keys(seaweedfs, bucket, "site/tus/") == [f"site/tus/{path[-36:]}"]  # no tail
    stored = seaweedfs.client().get_object(Bucket=bucket, Key=f"site/tus/{path[-36:]}")
    assert hashlib.sha256(stored["Body"].read()).hexdigest() == state["dataset"]["sha256"]


def test_a_replica_that_saw_part_of_it_reads_the_object_back(
    api: Api, large_recording: Path
) -> None:
    data = large_recording.read_bytes()
    path = create(api, len(data))
    patch(api, path, 0, data[:9_000_000])
    tus_hashes.clear()  # what another replica never had
    answer = patch(api, path, 9_000_000, data[9_000_000:])
    state = api.client.get(path, headers=api.headers).json()
    assert state["dataset"]["id"] == answer.headers["loceval-dataset"]
    assert state["dataset"]["sha256"] == hashlib.sha256(data).hexdigest()


def test_small_upload_is_one_object(api: Api, seaweedfs: SeaweedFS, bucket: str) -> None:
    data = b"# t x y z\n" + b"".join(f"{i}.0 {i}.5 0.0 1.0\n".encode() for i in range(100))
    path = create(api, len(data), filename="small.txt")
    patch(api, path, 0, data[:100])
    answer = patch(api, path, 100, data[100:])
    assert answer.headers["loceval-dataset"]
    assert open_multipart_uploads(seaweedfs, bucket) == []


def test_expired_and_terminated_uploads_leave_nothing(
    api: Api, large_recording: Path, seaweedfs: SeaweedFS, bucket: str
) -> None:
    data = large_recording.read_bytes()
    expiring = create(api, len(data))
    patch(api, expiring, 0, data[:10_000_000])  # a part and a tail
    terminated = create(api, len(data))
    patch(api, terminated, 0, data[:1_000])
    assert len(open_multipart_uploads(seaweedfs, bucket)) == 2
    assert object_keys(seaweedfs, bucket, "site/tus/")  # the tails
    answer = api.client.delete(terminated, headers={**api.headers, "Tus-Resumable": "1.0.0"})
    assert answer.status_code == 204
    later = dt.datetime.now(dt.UTC) + dt.timedelta(days=2)
    assert tus.sweep_expired(api.app.state.runtime, now=later) == 1
    assert open_multipart_uploads(seaweedfs, bucket) == []
    assert object_keys(seaweedfs, bucket, "site/tus/") == []
    assert not list((api.data_dir / "tus").glob("*.bin"))
