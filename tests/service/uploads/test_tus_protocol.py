"""The tus 1.0 protocol of ``/api/v1/uploads``, request by request (in-process, the folder).

Each answer is checked as the protocol says: creation, offsets, checksums, termination,
expiry, and the errors (460, 409, 413, 404, 412, 415) as problem documents; the upload
becomes the same dataset ``POST /datasets`` makes.
"""

from __future__ import annotations

import base64
import datetime as dt
import hashlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from service.db import TusUpload
from service.uploads import tus, tus_hashes
from tests.factories import make_trajectory, write_tum
from tests.service._api_fixtures import Api, assert_problem, open_api

TUS = {"Tus-Resumable": "1.0.0"}
OCTETS = {**TUS, "Content-Type": "application/offset+octet-stream"}


@pytest.fixture
def api(tmp_path: Path) -> Iterator[Api]:
    """The app with an upload limit of 64 MB."""
    with open_api(tmp_path, max_upload_bytes=64_000_000, min_free_bytes=0) as api:
        yield api


@pytest.fixture
def recording(tmp_path: Path, rng: np.random.Generator) -> bytes:
    """A TUM trajectory of about 1 MB."""
    return write_tum(tmp_path / "walk.txt", make_trajectory(rng, 12_000)).read_bytes()


def metadata(**values: str) -> str:
    """Return an ``Upload-Metadata`` header."""
    return ",".join(f"{k} {base64.b64encode(v.encode()).decode()}" for k, v in values.items())


def create(api: Api, length: int, *, headers: dict[str, str] | None = None, **meta: str) -> str:
    """Create an upload; return its path."""
    answer = api.client.post(
        "/api/v1/uploads",
        headers={
            **api.headers,
            **TUS,
            "Upload-Length": str(length),
            "Upload-Metadata": metadata(**meta),
            **(headers or {}),
        },
    )
    assert answer.status_code == 201, answer.text
    assert answer.headers["tus-resumable"] == "1.0.0"
    assert answer.headers["upload-offset"] == "0"
    location = answer.headers["location"]
    assert "/api/v1/uploads/" in location
    return "/api/v1/uploads/" + location.rsplit("/", 1)[1]


def patch(api: Api, path: str, offset: int, data: bytes, **headers: str) -> Any:
    """Send bytes at ``offset``."""
    return api.client.patch(
        path,
        content=data,
        headers={**api.headers, **OCTETS, "Upload-Offset": str(offset), **headers},
    )


def offset_of(api: Api, path: str) -> int:
    """Return the upload's offset (HEAD)."""
    answer = api.client.head(path, headers={**api.headers, **TUS})
    assert answer.status_code == 200
    assert answer.headers["cache-control"] == "no-store"
    return int(answer.headers["upload-offset"])


def test_options_announce_the_capabilities(api: Api) -> None:
    answer = api.client.options("/api/v1/uploads", headers=api.headers)
    assert answer.status_code == 204
    assert answer.headers["tus-version"] == "1.0.0"
    assert answer.headers["tus-resumable"] == "1.0.0"
    assert answer.headers["tus-max-size"] == "64000000"
    assert set(answer.headers["tus-extension"].split(",")) == {
        "creation",
        "creation-with-upload",
        "termination",
        "checksum",
        "expiration",
    }
    assert set(answer.headers["tus-checksum-algorithm"].split(",")) == {"sha1", "sha256", "md5"}
    assert "Upload-Offset" in answer.headers["access-control-expose-headers"]


def test_upload_in_parts_becomes_the_dataset(api: Api, recording: bytes) -> None:
    path = create(api, len(recording), filename="walk.txt", name="Level 2 walk", tags="a, b")
    head = api.client.head(path, headers={**api.headers, **TUS})
    assert head.headers["upload-length"] == str(len(recording))
    assert head.headers["upload-metadata"].startswith("filename ")
    assert head.headers["upload-expires"].endswith("GMT")
    step = 300_000
    for start in range(0, len(recording), step):
        assert offset_of(api, path) == start
        answer = patch(api, path, start, recording[start : start + step])
        assert answer.status_code == 204, answer.text
        assert answer.headers["upload-offset"] == str(min(start + step, len(recording)))
    dataset_id = answer.headers["loceval-dataset"]
    state = api.client.get(path, headers=api.headers).json()
    assert state["offset"] == state["length"] == len(recording)
    assert state["filename"] == "walk.txt"
    assert state["name"] == "Level 2 walk"
    assert state["tags"] == ["a", "b"]
    assert state["dataset"]["id"] == dataset_id
    assert state["dataset"]["sha256"] == hashlib.sha256(recording).hexdigest()
    assert state["dataset"]["name"] == "Level 2 walk"
    assert state["upload"]["deduplicated"] is False
    dataset = api.client.get(f"/api/v1/datasets/{dataset_id}", headers=api.headers).json()
    assert dataset == state["dataset"]
    assert dataset["inspection"]["kind"]
    assert not list((api.data_dir / "tus").glob("*.bin"))  # renamed into the dataset


def test_identical_bytes_merge_as_post_datasets_does(api: Api, recording: bytes) -> None:
    first = api.dataset("walk.txt", recording, tags="a")
    path = create(api, len(recording), filename="again.txt", tags="b")
    answer = patch(api, path, 0, recording)
    assert answer.headers["loceval-dataset"] == first["id"]
    state = api.client.get(path, headers=api.headers).json()
    assert state["upload"]["deduplicated"] is True
    assert state["upload"]["tags_added"] == ["b"]
    assert state["dataset"]["tags"] == ["a", "b"]
    assert not list((api.data_dir / "tus").glob("*.bin"))


def test_creation_with_upload(api: Api, recording: bytes) -> None:
    answer = api.client.post(
        "/api/v1/uploads",
        content=recording[:1000],
        headers={**api.headers, **OCTETS, "Upload-Length": str(len(recording))},
    )
    assert answer.status_code == 201, answer.text
    assert answer.headers["upload-offset"] == "1000"
    path = "/api/v1/uploads/" + answer.headers["location"].rsplit("/", 1)[1]
    assert patch(api, path, 1000, recording[1000:]).headers["loceval-dataset"]


def test_checksum_mismatch_is_460_and_keeps_nothing(api: Api, recording: bytes) -> None:
    path = create(api, len(recording))
    good = base64.b64encode(hashlib.sha1(recording[:5000]).digest()).decode()  # noqa: S324
    bad = base64.b64encode(hashlib.sha1(b"other").digest()).decode()  # noqa: S324
    answer = patch(api, path, 0, recording[:5000], **{"Upload-Checksum": f"sha1 {bad}"})
    assert_problem(answer, 460, type_="upload.checksum_mismatch")
    assert answer.headers["tus-resumable"] == "1.0.0"
    assert offset_of(api, path) == 0
    answer = patch(api, path, 0, recording[:5000], **{"Upload-Checksum": f"sha1 {good}"})
    assert answer.status_code == 204
    assert offset_of(api, path) == 5000
    sha256 = base64.b64encode(hashlib.sha256(recording[5000:]).digest()).decode()
    answer = patch(api, path, 5000, recording[5000:], **{"Upload-Checksum": f"sha256 {sha256}"})
    assert answer.headers["loceval-dataset"]
    answer = patch(api, path, len(recording), b"", **{"Upload-Checksum": "crc32 AAAA"})
    assert_problem(answer, 400, type_="upload.invalid", detail="sha1, sha256, md5")


def test_wrong_offset_is_409(api: Api, recording: bytes) -> None:
    path = create(api, len(recording))
    assert patch(api, path, 0, recording[:100]).status_code == 204
    assert_problem(patch(api, path, 0, recording[:100]), 409, type_="upload.offset_mismatch")
    assert_problem(patch(api, path, 200, recording[200:300]), 409, detail="stands at byte 100")
    assert offset_of(api, path) == 100


def test_more_than_the_length_is_413(api: Api, recording: bytes) -> None:
    path = create(api, 100)
    assert_problem(patch(api, path, 0, recording[:101]), 413, type_="upload.too_large")
    assert offset_of(api, path) == 0


def test_declared_length_over_the_limit_is_413_at_creation(api: Api) -> None:
    answer = api.client.post(
        "/api/v1/uploads", headers={**api.headers, **TUS, "Upload-Length": "64000001"}
    )
    assert_problem(answer, 413, type_="upload.too_large", detail="Tus-Max-Size")
    assert answer.headers["tus-resumable"] == "1.0.0"
    with api.app.state.runtime.sessions() as session:
        assert session.query(TusUpload).count() == 0


@pytest.mark.parametrize(
    ("headers", "detail"),
    [
        ({}, "Upload-Length"),
        ({"Upload-Length": "-1"}, "non-negative integer"),
        ({"Upload-Length": "10", "Upload-Metadata": "filename !!!"}, "base64"),
        ({"Upload-Length": "10", "Upload-Metadata": metadata(colour="red")}, "colour"),
    ],
)
def test_malformed_creation_is_400(api: Api, headers: dict[str, str], detail: str) -> None:
    answer = api.client.post("/api/v1/uploads", headers={**api.headers, **TUS, **headers})
    assert_problem(answer, 400, type_="upload.invalid", detail=detail)


def test_tags_over_the_limit_are_422_at_creation(api: Api) -> None:
    answer = api.client.post(
        "/api/v1/uploads",
        headers={
            **api.headers,
            **TUS,
            "Upload-Length": "10",
            "Upload-Metadata": metadata(tags="x" * 200),
        },
    )
    assert_problem(answer, 422, type_="request.invalid")


def test_unknown_and_other_projects_uploads_are_404(api: Api, recording: bytes) -> None:
    path = create(api, len(recording))
    other = {**api.other_headers, **TUS}
    for answer in (
        api.client.head(path, headers=other),
        api.client.get(path, headers=other),
        api.client.delete(path, headers=other),
        api.client.patch(path, content=b"x", headers={**other, **OCTETS, "Upload-Offset": "0"}),
    ):
        assert answer.status_code == 404, answer.text
        assert answer.headers["tus-resumable"] == "1.0.0"
    unknown = "/api/v1/uploads/00000000-0000-4000-8000-000000000000"
    assert_problem(patch(api, unknown, 0, b"x"), 404, type_="not_found")
    assert_problem(api.client.get(unknown, headers=api.headers), 404)
    assert api.client.head(unknown, headers={**api.headers, **TUS}).status_code == 404
    assert offset_of(api, path) == 0


def test_missing_version_is_412_and_wrong_type_415(api: Api) -> None:
    path = create(api, 10)
    answer = api.client.patch(
        path,
        content=b"x",
        headers={
            **api.headers,
            "Content-Type": "application/offset+octet-stream",
            "Upload-Offset": "0",
        },
    )
    assert_problem(answer, 412, type_="upload.tus_version")
    assert answer.headers["tus-version"] == "1.0.0"
    answer = api.client.post(
        "/api/v1/uploads", headers={**api.headers, "Tus-Resumable": "0.2.2", "Upload-Length": "1"}
    )
    assert_problem(answer, 412)
    answer = api.client.patch(
        path,
        content=b"x",
        headers={**api.headers, **TUS, "Content-Type": "text/plain", "Upload-Offset": "0"},
    )
    assert_problem(answer, 415, type_="upload.media_type")


def test_no_key_is_401_with_the_tus_header(api: Api) -> None:
    answer = api.client.post("/api/v1/uploads", headers={**TUS, "Upload-Length": "1"})
    assert_problem(answer, 401)
    assert answer.headers["tus-resumable"] == "1.0.0"


def test_termination_removes_the_parts(api: Api, recording: bytes) -> None:
    path = create(api, len(recording))
    patch(api, path, 0, recording[:1000])
    assert list((api.data_dir / "tus").glob("*.bin"))
    answer = api.client.delete(path, headers={**api.headers, **TUS})
    assert answer.status_code == 204
    assert not list((api.data_dir / "tus").iterdir())
    assert api.client.head(path, headers={**api.headers, **TUS}).status_code == 404


def test_expired_upload_leaves_nothing(api: Api, recording: bytes) -> None:
    runtime = api.app.state.runtime
    unfinished = create(api, len(recording))
    patch(api, unfinished, 0, recording[:1000])
    finished = create(api, len(recording))
    dataset_id = patch(api, finished, 0, recording).headers["loceval-dataset"]
    assert tus.sweep_expired(runtime) == 0
    later = dt.datetime.now(dt.UTC) + dt.timedelta(days=2)
    assert tus.sweep_expired(runtime, now=later) == 2
    assert not list((api.data_dir / "tus").iterdir())
    for path in (unfinished, finished):
        assert api.client.head(path, headers={**api.headers, **TUS}).status_code == 404
    assert api.client.get(f"/api/v1/datasets/{dataset_id}", headers=api.headers).status_code == 200


def test_a_file_that_is_no_recording_is_refused_at_its_last_byte(api: Api) -> None:
    data = b"\x00\x01 not a recording " * 100
    path = create(api, len(data), filename="noise.bin")
    answer = patch(api, path, 0, data)
    assert_problem(answer, 422)
    state = api.client.get(path, headers=api.headers).json()
    assert state["dataset"] is None
    assert state["error"]["status"] == 422
    assert not list((api.data_dir / "tus").glob("*.bin"))
    assert not list((api.data_dir / "datasets").iterdir())


def test_a_process_that_saw_part_of_the_bytes_reads_them_back(api: Api, recording: bytes) -> None:
    """The SHA-256 of bytes another replica (or an earlier process) received is computed."""
    path = create(api, len(recording))
    patch(api, path, 0, recording[:4000])
    tus_hashes.clear()  # what a restart forgets
    answer = patch(api, path, 4000, recording[4000:])
    dataset = api.client.get(
        f"/api/v1/datasets/{answer.headers['loceval-dataset']}", headers=api.headers
    ).json()
    assert dataset["sha256"] == hashlib.sha256(recording).hexdigest()
