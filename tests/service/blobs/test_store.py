"""The S3 backend against a real SeaweedFS: streaming uploads, dedup, aborts, sweeps, cache."""

from __future__ import annotations

import hashlib
import os
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import anyio
import numpy as np
import pytest
from starlette.requests import Request

from service.api.downloads import download_response
from service.api.multipart import receive_multipart
from service.blobs import LocalBlobs, artifact_key
from service.blobs.base import download_filename
from service.blobs.s3 import PART_BYTES, S3Blobs
from service.errors import InsufficientStorageError, UploadError
from tests.service.blobs.conftest import SeaweedFS, object_keys, open_multipart_uploads

BOUNDARY = "loceval-s3-boundary"


_OPENED: list[S3Blobs] = []
"""The stores a test opened; closed after it (their lease threads stop, leases go)."""


def _store(bucket: str, root: Path, **kwargs: Any) -> S3Blobs:
    values: dict[str, Any] = {"cache_bytes": 1 << 30, "min_free_bytes": 0, **kwargs}
    store = S3Blobs(f"s3://{bucket}/team", root, **values)
    _OPENED.append(store)
    store.check_bucket()
    return store


@pytest.fixture(autouse=True)
def _close_stores() -> Iterator[None]:
    yield
    while _OPENED:
        _OPENED.pop().close()


@pytest.fixture
def store(bucket: str, s3_env: dict[str, str], tmp_path: Path) -> S3Blobs:
    """An S3 store on a fresh bucket, prefix ``team/``."""
    del s3_env
    return _store(bucket, tmp_path / "data")


def _payload(size: int, seed: int = 0) -> bytes:
    return np.random.default_rng(seed).bytes(size)


def _send(store: S3Blobs, data: bytes, chunk: int = 1 << 16) -> Any:
    incoming = store.open_incoming()
    for start in range(0, len(data), chunk):
        incoming.write(data[start : start + chunk])
    incoming.commit()
    return incoming


def _uploads(server: SeaweedFS, bucket: str) -> list[str]:
    """Return the bucket's objects but the processes' leases (``instances/``)."""
    return [k for k in object_keys(server, bucket) if "/instances/" not in k]


def test_upload_streams_as_multipart_and_is_completed_in_place(
    store: S3Blobs, seaweedfs: SeaweedFS, bucket: str
) -> None:
    """2.5 parts in 64 KiB writes: one object under uploads/<instance>/<uuid>, never copied."""
    data = _payload(PART_BYTES * 5 // 2)
    sha = hashlib.sha256(data).hexdigest()
    incoming = _send(store, data)
    assert len(incoming._parts) == 3  # two full parts and the rest: a real multipart upload
    assert incoming.head == data[:64]
    assert _uploads(seaweedfs, bucket) == []  # committed: every part sent, nothing visible
    with store.publishing("d1"):
        key = store.publish_upload(
            incoming, project_id="p1", dataset_id="d1", filename="run.bag", sha256=sha
        )
        assert key == incoming.key == f"uploads/{store.instance}/{key.rsplit('/', 1)[1]}"
        assert _uploads(seaweedfs, bucket) == [f"team/pending/{key[8:]}", f"team/{key}"]
        assert store.read_bytes(f"pending/{key[8:]}") == b"d1"  # the sweep's note
    assert _uploads(seaweedfs, bucket) == [f"team/{key}"]  # recorded: the marker went
    assert store.read_bytes(key) == data
    assert open_multipart_uploads(seaweedfs, bucket) == []
    incoming.abort()  # discarding the request's form keeps a recorded upload
    assert store.read_bytes(key) == data


def test_same_bytes_twice_are_stored_once(
    store: S3Blobs, seaweedfs: SeaweedFS, bucket: str
) -> None:
    """A second upload of identical bytes (found in the database) is aborted: never an object."""
    data = _payload(PART_BYTES + (3 << 20), seed=1)
    sha = hashlib.sha256(data).hexdigest()
    with store.publishing("d0"):
        key = store.publish_upload(
            _send(store, data), project_id="p", dataset_id="d0", filename="a.txt", sha256=sha
        )
    second = _send(store, data)
    assert open_multipart_uploads(seaweedfs, bucket) == [second._full_key]
    second.abort()  # what datasets.store_upload does when the project has these bytes
    assert _uploads(seaweedfs, bucket) == [f"team/{key}"]
    assert open_multipart_uploads(seaweedfs, bucket) == []


def test_aborted_upload_leaves_no_object_and_no_multipart_upload(
    store: S3Blobs, seaweedfs: SeaweedFS, bucket: str
) -> None:
    """Abort after two parts were sent: the multipart upload is gone, no object appeared."""
    incoming = store.open_incoming()
    data = _payload(PART_BYTES * 2 + 100, seed=2)
    incoming.write(data)
    assert open_multipart_uploads(seaweedfs, bucket) != []  # it was really under way
    incoming.abort()
    incoming.abort()  # twice is harmless
    assert open_multipart_uploads(seaweedfs, bucket) == []
    assert _uploads(seaweedfs, bucket) == []


def _request(chunks: list[bytes], *, disconnect: bool) -> Request:
    messages = [{"type": "http.request", "body": c, "more_body": True} for c in chunks]
    messages.append(
        {"type": "http.disconnect"}
        if disconnect
        else {"type": "http.request", "body": b"", "more_body": False}
    )

    async def receive() -> dict[str, Any]:
        return messages.pop(0)

    scope = {
        "type": "http",
        "method": "POST",
        "path": "/upload",
        "headers": [(b"content-type", f"multipart/form-data; boundary={BOUNDARY}".encode())],
        "query_string": b"",
    }
    return Request(scope, receive)


def _form_chunks(data: bytes, chunk: int = 1 << 20) -> list[bytes]:
    head = (
        f'--{BOUNDARY}\r\nContent-Disposition: form-data; name="file"; filename="big.bag"\r\n'
        "Content-Type: application/octet-stream\r\n\r\n"
    ).encode()
    body = head + data + f"\r\n--{BOUNDARY}--\r\n".encode()
    return [body[i : i + chunk] for i in range(0, len(body), chunk)]


def test_client_gone_mid_upload_leaves_nothing(
    store: S3Blobs, seaweedfs: SeaweedFS, bucket: str
) -> None:
    """The client disconnects after 20 MB of a form: 400-class error, no object, no upload."""
    chunks = _form_chunks(_payload(30 << 20, seed=3))[:20]

    async def run() -> None:
        await receive_multipart(
            _request(chunks, disconnect=True),
            store,
            max_bytes=1 << 30,
            file_fields=frozenset({"file"}),
        )

    with pytest.raises(UploadError, match="interrupted"):
        anyio.run(run)
    assert open_multipart_uploads(seaweedfs, bucket) == []
    assert _uploads(seaweedfs, bucket) == []


def test_received_form_hashes_while_streaming(store: S3Blobs) -> None:
    """A whole form: the file's SHA-256 and size are known when the body ends."""
    data = _payload(12 << 20, seed=4)

    async def run() -> Any:
        return await receive_multipart(
            _request(_form_chunks(data), disconnect=False),
            store,
            max_bytes=1 << 30,
            file_fields=frozenset({"file"}),
        )

    form = anyio.run(run)
    received = form.files[0]
    assert (received.size, received.sha256) == (len(data), hashlib.sha256(data).hexdigest())
    form.discard()


def test_startup_sweep_aborts_own_uploads_and_the_hourly_one_only_stale(
    store: S3Blobs, seaweedfs: SeaweedFS, bucket: str
) -> None:
    """An upload left open by a crash: the age sweep keeps it (fresh), the start-up one aborts."""
    left = store.open_incoming()
    left.write(_payload(PART_BYTES + 1, seed=5))  # one part sent, then "the process died"
    assert open_multipart_uploads(seaweedfs, bucket) != []
    assert store.sweep().partial_uploads == 0  # an hour has not passed: maybe another API's upload
    assert store.sweep(startup=True).partial_uploads == 1
    assert open_multipart_uploads(seaweedfs, bucket) == []
    assert store.sweep(older_than_s=0).partial_uploads == 0


def test_artifacts_publish_read_download_and_remove(store: S3Blobs, tmp_path: Path) -> None:
    """Staged files go to evaluations/<id>/artifacts/; a new attempt replaces them whole."""
    staging = store.job_staging_dir("evaluations", "e1")
    staging.mkdir()
    (staging / "result.json").write_text('{"ok": true}')
    (staging / "errors.csv").write_text("t,e\n")
    assert store.publish_job_artifacts("evaluations", "e1", staging) == staging
    assert store.exists(artifact_key("evaluations", "e1", "errors.csv"))
    assert store.read_bytes(artifact_key("evaluations", "e1", "result.json")) == b'{"ok": true}'
    assert set(store.job_ids("evaluations")) == {"e1"}
    again = store.job_staging_dir("evaluations", "e1")
    again.mkdir()
    (again / "result.json").write_text("{}")
    store.publish_job_artifacts("evaluations", "e1", again)
    assert not store.exists(artifact_key("evaluations", "e1", "errors.csv"))
    store.remove_job("evaluations", "e1")
    assert store.job_ids("evaluations") == {}
    assert not (tmp_path / "data" / "staging" / "evaluations" / "e1").exists()


def test_download_streams_or_redirects(bucket: str, s3_env: dict[str, str], tmp_path: Path) -> None:
    """A download streams the object with its length, or is a 307 to a presigned URL."""
    del s3_env
    import httpx2

    store = _store(bucket, tmp_path / "a")
    staging = store.job_staging_dir("runs", "r1")
    staging.mkdir()
    (staging / "summary.html").write_text("<p>hi</p>")
    store.publish_job_artifacts("runs", "r1", staging)
    key = artifact_key("runs", "r1", "summary.html")
    streamed = download_response(store, key, media_type="text/html", filename="s.html", inline=True)
    assert streamed.headers["content-length"] == "9"
    redirecting = _store(bucket, tmp_path / "b", redirect_s=60)
    moved = download_response(
        redirecting, key, media_type="text/html", filename="s.html", inline=True
    )
    assert moved.status_code == 307
    fetched = httpx2.get(moved.headers["location"])
    assert fetched.status_code == 200
    assert fetched.content == b"<p>hi</p>"
    assert fetched.headers["content-disposition"] == 'inline; filename="s.html"'


NAMED = [
    ("fr2_desk_ORB", 'attachment; filename="fr2_desk_ORB-report.pdf"'),
    (
        "Müller Büro 東",
        (
            'attachment; filename="Muller_Buro_-report.pdf"; '
            "filename*=UTF-8''M%C3%BCller_B%C3%BCro_%E6%9D%B1-report.pdf"
        ),
    ),
]


@pytest.mark.parametrize(("stem", "header"), NAMED, ids=["ascii", "non-ascii"])
def test_downloads_are_named_after_their_evaluation_by_folder_and_bucket(
    bucket: str, s3_env: dict[str, str], tmp_path: Path, stem: str, header: str
) -> None:
    """Folder, bucket stream and presigned redirect: the same RFC 6266 attachment name."""
    del s3_env
    import httpx2

    filename = download_filename(stem, "report.pdf", default="e1")
    folder = LocalBlobs(tmp_path / "folder")
    stores = [folder, _store(bucket, tmp_path / "a"), _store(bucket, tmp_path / "b", redirect_s=60)]
    for store in stores:
        staging = store.job_staging_dir("evaluations", "e1")
        staging.mkdir(exist_ok=True)
        (staging / "report.pdf").write_bytes(b"%PDF-1.7 x")
        store.publish_job_artifacts("evaluations", "e1", staging)
        key = artifact_key("evaluations", "e1", "report.pdf")
        answer = download_response(
            store, key, media_type="application/pdf", filename=filename, inline=False
        )
        if answer.status_code == 307:  # the bucket answers the presigned URL with the name
            fetched = httpx2.get(answer.headers["location"])
            assert fetched.content == b"%PDF-1.7 x"
            assert fetched.headers["content-disposition"] == header
        else:
            assert answer.headers["content-disposition"] == header, store.kind
    folder.close()


def _dataset(store: S3Blobs, data: bytes, project: str = "p") -> tuple[str, str]:
    sha = hashlib.sha256(data).hexdigest()
    with store.publishing("d"):
        key = store.publish_upload(
            _send(store, data), project_id=project, dataset_id="d", filename="x.txt", sha256=sha
        )
    return key, sha


def test_cache_fetches_once_and_evicts_the_least_recently_used(
    bucket: str, s3_env: dict[str, str], tmp_path: Path
) -> None:
    """A 3 MB cache holds two 1.2 MB inputs: a third evicts the older, a pinned one stays."""
    del s3_env
    store = _store(bucket, tmp_path / "w", cache_bytes=3_000_000)
    blobs = [_dataset(store, _payload(1_200_000, seed=10 + k)) for k in range(3)]
    first = store.local_path(blobs[0][0], filename="a.bag", sha256=blobs[0][1])
    assert first.name == "a.bag"
    assert first.parent.name == blobs[0][1]
    first_inode = first.stat().st_ino
    assert store.local_path(blobs[0][0], filename="a.bag", sha256=blobs[0][1]).stat().st_ino == (
        first_inode
    )  # no second download
    os.utime(first, (1, 1))  # long unused
    with store.pinned():
        second = store.local_path(blobs[1][0], filename="b.bag", sha256=blobs[1][1])
        os.utime(second, (0, 0))  # older still, but pinned by this block
        third = store.local_path(blobs[2][0], filename="c.bag", sha256=blobs[2][1])
        assert second.is_file()
        assert not first.exists()  # the unpinned, least recently used copy went
        assert third.read_bytes() == store.read_bytes(blobs[2][0])
    assert store.cache.size() <= 3_000_000


def test_cache_refuses_an_input_larger_than_itself(
    bucket: str, s3_env: dict[str, str], tmp_path: Path
) -> None:
    """An input over the cache's size fails with the setting to raise."""
    del s3_env
    store = _store(bucket, tmp_path / "w", cache_bytes=1 << 20)
    key, sha = _dataset(store, _payload(2 << 20, seed=20))
    with pytest.raises(InsufficientStorageError, match="LOCEVAL_BLOB_CACHE_BYTES"):
        store.local_path(key, filename="big.bag", sha256=sha)


def test_two_threads_fetch_one_copy(bucket: str, s3_env: dict[str, str], tmp_path: Path) -> None:
    """Two jobs wanting the same input at once download it once and both read it whole."""
    del s3_env
    store = _store(bucket, tmp_path / "w")
    data = _payload(9 << 20, seed=30)
    key, sha = _dataset(store, data)
    paths: list[Path] = []

    def fetch() -> None:
        with store.pinned():
            path = store.local_path(key, filename="r.bag", sha256=sha)
            assert path.read_bytes() == data
            paths.append(path)

    threads = [threading.Thread(target=fetch) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(paths) == 2
    assert paths[0] == paths[1]
    assert [p.name for p in paths[0].parent.iterdir() if p.name != ".lock"] == ["r.bag"]


def test_unreachable_store_is_a_clear_startup_error(tmp_path: Path, monkeypatch: Any) -> None:
    """A bucket behind a closed port: StartupError naming the bucket and the variables."""
    from service.errors import StartupError
    from tests.service.conftest import free_port

    monkeypatch.setenv("AWS_ENDPOINT_URL", f"http://127.0.0.1:{free_port()}")
    monkeypatch.setenv("AWS_ACCESS_KEY_ID", "x")
    monkeypatch.setenv("AWS_SECRET_ACCESS_KEY", "y")
    store = S3Blobs("s3://nowhere/p", tmp_path, cache_bytes=1 << 20, min_free_bytes=0)
    store.client.meta.config.retries = {"max_attempts": 1}
    with pytest.raises(StartupError, match=r"'nowhere'.*AWS_ENDPOINT_URL"):
        store.check_bucket()


def test_one_job_reads_the_same_input_twice(
    bucket: str, s3_env: dict[str, str], tmp_path: Path
) -> None:
    """A bag that is reference and estimate at once: the second fetch reuses the pinned copy."""
    del s3_env
    store = _store(bucket, tmp_path / "w")
    key, sha = _dataset(store, _payload(1 << 20, seed=40))
    with store.pinned():
        first = store.local_path(key, filename="both.bag", sha256=sha)
        second = store.local_path(key, filename="both.bag", sha256=sha)  # must not wait
    assert first == second


def _mcap(folder: Path, compression: str | None = None) -> bytes:
    """Return a small MCAP camera bag (tf and images), its chunks zstd-compressed if asked."""
    import tests.bagfactory as bf

    poses = bf.random_poses(np.random.default_rng(3), 40, dt_ns=50_000_000)
    records = bf.tf_records(bf.link_transforms("map", "base_link", poses))
    records += [bf.image_record("/camera", int(t), size=32) for t in poses.stamps_ns]
    bag = bf.write_bag(folder, records, fmt="mcap", compression=compression)
    return next(bag.glob("*.mcap")).read_bytes()


def test_a_job_reads_a_large_indexed_mcap_where_it_lies_and_other_files_from_the_cache(
    bucket: str, s3_env: dict[str, str], tmp_path: Path
) -> None:
    """job_input: an uncompressed MCAP file from the size on is read by ranges; a smaller
    one, a compressed one, a ROS 1 bag, another file and one the cache holds are not."""
    import pickle

    from service.blobs.ranged import ObjectFile

    del s3_env
    plain, packed = _mcap(tmp_path / "plain"), _mcap(tmp_path / "packed", "storage")
    store = _store(bucket, tmp_path / "w", ranged_bytes=min(len(plain), len(packed)))
    (plain_key, plain_sha), (packed_key, packed_sha) = (
        _dataset(store, plain),
        _dataset(store, packed),
    )
    remote = store.job_input(plain_key, filename="cam.mcap", sha256=plain_sha, size=len(plain))
    assert isinstance(remote, ObjectFile)
    reopened = pickle.loads(pickle.dumps(remote))  # noqa: S301  (our own bytes: a job process's copy)
    assert reopened.size == len(plain)
    assert reopened.pread(len(plain), 0) == plain
    assert reopened._client is not store.client
    store.ranged_bytes = len(plain) + 1
    small = store.job_input(plain_key, filename="cam.mcap", sha256=plain_sha, size=len(plain))
    assert small is None  # under the setting: copied
    store.ranged_bytes = min(len(plain), len(packed))
    for filename in ("cam.bag", "cam.db3", "cam.txt"):
        assert store.job_input(plain_key, filename=filename, sha256=plain_sha, size=1 << 40) is None
    assert packed_sha != plain_sha
    compressed = store.job_input(
        packed_key, filename="cam.mcap", sha256=packed_sha, size=len(packed)
    )
    assert compressed is None  # zstd chunks: the index cannot serve a few topics
    with store.pinned():
        store.local_path(plain_key, filename="cam.mcap", sha256=plain_sha)
    cached = store.job_input(plain_key, filename="cam.mcap", sha256=plain_sha, size=len(plain))
    assert cached is None  # this machine has a copy already
