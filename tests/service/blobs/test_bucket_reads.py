"""A bag in the bucket at the store's speed: streamed in whole, read back by what is needed.

An upload streams through the API into a multipart upload and arrives byte for byte; a
connection cut mid-body leaves neither an object nor an open multipart upload; an
evaluation of a camera bag fetches its tf and poses (held as the upload streamed past) and
a few index records, not the images, and gives the numbers the same evaluation gives from
a data folder. The bytes fetched are counted by a relay between the service and the store
(:class:`tests.service.blobs.conftest.Gate`), independent of the service's own counters.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import tests.bagfactory as bf
from service.uploads import tus_hashes
from tests.service._api_fixtures import open_api
from tests.service.blobs.conftest import Gate, SeaweedFS, object_keys, open_multipart_uploads
from tests.service.conftest import start_cut_upload, start_server, wait_until
from tests.service.uploads.test_tus_protocol import create, patch

IMAGES = 120
IMAGE_SIDE = 256  # rgb8: 196 KB an image, 23.6 MB of images in all


def _camera_bag(folder: Path, rng: np.random.Generator) -> Path:
    """An MCAP bag: a tf chain at 50 Hz, a pose topic at 20 Hz and large images at 15 Hz."""
    poses = bf.random_poses(rng, 400, dt_ns=20_000_000)
    noisy = bf.Poses(
        poses.stamps_ns, poses.positions + rng.normal(scale=0.02, size=(400, 3)), poses.quats
    )
    records = bf.tf_records(bf.link_transforms("map", "base_link", noisy))
    truth = bf.Poses(poses.stamps_ns[::2], poses.positions[::2], poses.quats[::2])
    records += bf.pose_records("/gt", bf.POSE, truth)
    records += [
        bf.image_record("/camera/image", bf.T0_NS + i * 66_666_667, size=IMAGE_SIDE)
        for i in range(IMAGES)
    ]
    return next(bf.write_bag(folder / "cam", records, fmt="mcap").glob("*.mcap"))


@pytest.fixture
def gate(
    seaweedfs: SeaweedFS, s3_env: dict[str, str], monkeypatch: pytest.MonkeyPatch
) -> Iterator[Gate]:
    """A relay the service reaches the store through: every byte the store answers counted."""
    del s3_env
    relay = Gate(seaweedfs)
    monkeypatch.setenv("AWS_ENDPOINT_URL", relay.endpoint)
    yield relay
    relay.shut()


def _evaluate(api: Any, dataset_id: str) -> dict[str, Any]:
    """Evaluate the bag's tf chain against its pose topic; return the result document."""
    answer = api.evaluate(
        {
            "reference": {"dataset_id": dataset_id, "selector": "/gt"},
            "estimates": [{"dataset_id": dataset_id, "selector": "tf:map:base_link"}],
            "options": {"formats": ["result.json"]},
        }
    )
    assert answer.status_code == 202, answer.text
    evaluation = answer.json()
    assert evaluation["status"] == "succeeded", evaluation
    url = f"/api/v1/evaluations/{evaluation['id']}"
    result: dict[str, Any] = api.client.get(url, headers=api.headers).json()["result"]
    return result


def test_a_camera_bag_streams_in_whole_and_is_evaluated_from_a_fraction_of_it(
    seaweedfs: SeaweedFS, bucket: str, gate: Gate, rng: np.random.Generator, tmp_path: Path
) -> None:
    """Upload through the API: the object is the file, byte for byte, with its SHA-256.
    Evaluate it from the bucket: the store answers well under a tenth of the bag (its
    tf and poses, a few index records; never the images), nothing is copied into the
    input cache, and the numbers equal the same evaluation from a data folder. Deleting
    the dataset deletes its held messages with it."""
    mcap = _camera_bag(tmp_path, rng)
    content = mcap.read_bytes()
    assert len(content) > IMAGES * IMAGE_SIDE**2 * 3  # mostly images
    with open_api(tmp_path / "s3", blob_url=f"s3://{bucket}/site", blob_ranged_bytes=0) as api:
        dataset = api.dataset("cam.mcap", content)
        assert dataset["sha256"] == hashlib.sha256(content).hexdigest()
        assert dataset["size_bytes"] == len(content)
        [key] = object_keys(seaweedfs, bucket, "site/uploads/")
        stored = seaweedfs.client().get_object(Bucket=bucket, Key=key)["Body"].read()
        assert stored == content  # byte for byte: no part lost, doubled or reordered
        held = "site/held/" + key.removeprefix("site/uploads/")
        assert object_keys(seaweedfs, bucket, "site/held/") == [held]
        assert open_multipart_uploads(seaweedfs, bucket) == []
        before = gate.answered_bytes
        from_bucket = _evaluate(api, dataset["id"])
        fetched = gate.answered_bytes - before
        cache = api.data_dir / "cache"
        assert [p for p in cache.rglob("*") if p.is_file() and p.name != ".lock"] == []
        deleted = api.client.delete(f"/api/v1/datasets/{dataset['id']}", headers=api.headers)
        assert deleted.status_code == 204, deleted.text
        assert object_keys(seaweedfs, bucket, "site/uploads/") == []
        assert object_keys(seaweedfs, bucket, "site/held/") == []  # gone with its bag
    assert fetched < len(content) / 10, f"{fetched} of {len(content)} bytes fetched"
    with open_api(tmp_path / "folder", min_free_bytes=0) as api:  # the disk is not the point
        from_folder = _evaluate(api, api.dataset("cam.mcap", content)["id"])
    assert from_bucket["estimates"] == from_folder["estimates"]
    assert from_bucket["estimates"][0]["matched"] == 399  # of 400: one lies past the reference
    for bucket_input, folder_input in zip(
        from_bucket["inputs"], from_folder["inputs"], strict=True
    ):
        del bucket_input["dataset_id"], folder_input["dataset_id"]  # two services' own ids
        assert bucket_input == folder_input


def test_an_evaluation_without_held_messages_reads_the_index_and_matches(
    seaweedfs: SeaweedFS, bucket: str, gate: Gate, rng: np.random.Generator, tmp_path: Path
) -> None:
    """An upload whose held messages are gone (an older upload, a damaged record) is read by
    ranges through the MCAP index: still a fraction of the bag, and the same numbers."""
    mcap = _camera_bag(tmp_path, rng)
    content = mcap.read_bytes()
    with open_api(tmp_path / "s3", blob_url=f"s3://{bucket}/site", blob_ranged_bytes=0) as api:
        dataset = api.dataset("cam.mcap", content)
        [held] = object_keys(seaweedfs, bucket, "site/held/")
        client = seaweedfs.client()
        client.put_object(Bucket=bucket, Key=held, Body=b"LOCEVAL-HELD-0\nsomething else")
        before = gate.answered_bytes
        damaged = _evaluate(api, dataset["id"])
        client.delete_object(Bucket=bucket, Key=held)
        missing = _evaluate(api, dataset["id"])
        fetched = gate.answered_bytes - before
    assert fetched < 2 * len(content) / 10, f"{fetched} of {len(content)} bytes fetched"
    assert damaged["estimates"] == missing["estimates"]
    assert damaged["estimates"][0]["matched"] == 399  # of 400: one lies past the reference


def test_a_resumable_upload_keeps_the_held_messages_too(
    seaweedfs: SeaweedFS, bucket: str, gate: Gate, rng: np.random.Generator, tmp_path: Path
) -> None:
    """A camera bag sent by tus in PATCHes that cut its records and 8 MiB parts keeps its tf
    and poses as ``POST /datasets`` does (``held/tus/<id>``): its evaluation fetches a
    fraction of the bag, and deleting the dataset deletes them. A process that did not see
    the upload from its first byte stores none, and the evaluation reads the index."""
    mcap = _camera_bag(tmp_path, rng)
    content = mcap.read_bytes()
    step = 3_000_001  # an odd size: every request ends inside a record
    with open_api(tmp_path / "s3", blob_url=f"s3://{bucket}/site", blob_ranged_bytes=0) as api:
        path = create(api, len(content), filename="cam.mcap")
        for start in range(0, len(content), step):
            answer = patch(api, path, start, content[start : start + step])
            assert answer.status_code == 204, answer.text
        dataset_id = answer.headers["loceval-dataset"]
        upload = path.rsplit("/", 1)[1]
        assert object_keys(seaweedfs, bucket, "site/held/") == [f"site/held/tus/{upload}"]
        before = gate.answered_bytes
        result = _evaluate(api, dataset_id)
        fetched = gate.answered_bytes - before
        assert result["estimates"][0]["matched"] == 399
        deleted = api.client.delete(f"/api/v1/datasets/{dataset_id}", headers=api.headers)
        assert deleted.status_code == 204, deleted.text
        assert object_keys(seaweedfs, bucket, "site/held/") == []
        assert fetched < len(content) / 10, f"{fetched} of {len(content)} bytes fetched"

        again = create(api, len(content), filename="cam.mcap")
        patch(api, again, 0, content[:step])
        tus_hashes.clear()  # what another replica, or this one restarted, never had
        answer = patch(api, again, step, content[step:])
        assert answer.status_code == 204, answer.text
        assert object_keys(seaweedfs, bucket, "site/held/") == []
        unheld = _evaluate(api, answer.headers["loceval-dataset"])
    assert unheld["estimates"] == result["estimates"]


def test_a_connection_dropped_mid_upload_leaves_no_object_and_no_open_upload(
    seaweedfs: SeaweedFS, bucket: str, tmp_path: Path
) -> None:
    """A real server: 40 MB of a 160 MB form arrive (parts are in the bucket), then the
    client's connection closes. The multipart upload is aborted, no object or held
    messages appear, and the server goes on serving."""
    env = {"LOCEVAL_BLOB_URL": f"s3://{bucket}/site", **seaweedfs.env()}
    server = start_server(tmp_path / "data", env=env, args=("--no-consumer",))
    try:
        body = np.random.default_rng(11).bytes(40 << 20)
        with start_cut_upload(server, body, declared=160 << 20, filename="big.mcap"):
            assert wait_until(lambda: open_multipart_uploads(seaweedfs, bucket), 60), (
                "the upload never reached the bucket"
            )
        assert wait_until(lambda: not open_multipart_uploads(seaweedfs, bucket), 60), (
            "the dropped upload's multipart upload stayed open"
        )
        leftovers = [k for k in object_keys(seaweedfs, bucket) if "/instances/" not in k]
        assert leftovers == []
        with server.client() as client:
            assert client.get("/api/v1/datasets").json()["count"] == 0
    finally:
        server.stop()


def test_a_job_process_reads_the_held_messages_in_one_request(
    bucket: str, s3_env: dict[str, str], rng: np.random.Generator, tmp_path: Path
) -> None:
    """job_input's file, pickled into a job's process as the worker does: the wanted tf and
    pose messages come from the held record (one GET of it), equal to the local file's."""
    import pickle

    from loceval.readers._mcap import read_indexed_messages
    from loceval.readers.rosbag import McapScan
    from service.blobs.ranged import ObjectFile
    from service.blobs.s3 import S3Blobs

    del s3_env
    content = _camera_bag(tmp_path, rng).read_bytes()
    store = S3Blobs(f"s3://{bucket}/site", tmp_path / "w", cache_bytes=1 << 30, min_free_bytes=0)
    try:
        incoming = store.open_incoming()
        scan = McapScan()
        for start in range(0, len(content), 1 << 20):
            incoming.write(content[start : start + (1 << 20)])
            scan.feed(content[start : start + (1 << 20)])
        incoming.commit()
        incoming.held = scan.finish()
        assert incoming.held is not None
        sha = hashlib.sha256(content).hexdigest()
        with store.publishing("d"):
            key = store.publish_upload(
                incoming, project_id="p", dataset_id="d", filename="cam.mcap", sha256=sha
            )
        store.ranged_bytes = 0
        remote = store.job_input(key, filename="cam.mcap", sha256=sha, size=len(content))
        assert isinstance(remote, ObjectFile)
        in_job = pickle.loads(pickle.dumps(remote))  # noqa: S301  (our own bytes: the job's copy)
        wanted = [("/tf", bf.TF), ("/gt", bf.POSE)]
        local = tmp_path / "cam.mcap"
        local.write_bytes(content)
        before = in_job.fetched_bytes
        assert read_indexed_messages(in_job, wanted) == read_indexed_messages(local, wanted)
        assert in_job.requests == 0  # no ranged read: the held record answered
        assert 0 < in_job.fetched_bytes - before == in_job.held_bytes < len(content) / 50
    finally:
        store.close()
