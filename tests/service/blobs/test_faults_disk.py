"""A full disk, on a real one: a 20 MB tmpfs holding the data folder and the SQLite database.

Every write route answers 507 with what to free (never 500), nothing of the refused request
is saved, ``/readyz`` is not ready while the free space is under the reserve, and a chunked
upload never eats into the reserve. Mounting needs root (or CAP_SYS_ADMIN): elsewhere these
tests skip, saying so.
"""

from __future__ import annotations

import shutil
import subprocess
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.factories import make_trajectory, perturb, write_tum
from tests.service._api_fixtures import PROBLEM_JSON, Api, open_api, schedule_body

MB = 1_000_000


@pytest.fixture
def disk(tmp_path: Path) -> Iterator[Path]:
    """A fresh 20 MB tmpfs, unmounted afterwards."""
    mount = tmp_path / "disk"
    mount.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=20m", "tmpfs", str(mount)],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here (needs root): {done.stderr.strip()}")
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=False)


def _fill(disk: Path, *, leave: int = 0) -> Path:
    """Write a filler file until only ``leave`` bytes are free (0: until the disk is full)."""
    filler = disk / "filler"
    # unbuffered: a buffered file would keep the bytes the full disk refused and raise
    # ENOSPC again when it is closed
    with filler.open("wb", buffering=0) as fh:
        if leave:
            fh.write(b"\0" * (shutil.disk_usage(disk).free - leave))
            return filler
        try:
            while True:
                fh.write(b"\0" * 65536)
        except OSError:
            pass
    return filler


def _assert_storage_full(answer: Any) -> None:
    assert answer.status_code == 507, (answer.request.method, answer.request.url, answer.text)
    assert answer.headers["content-type"].startswith(PROBLEM_JSON)
    body = answer.json()
    assert body["type"] == "storage.full"
    assert "free space" in body["detail"]
    assert "LOCEVAL_DATA_DIR" in body["detail"]


def _tum(tmp_path: Path, rng: np.random.Generator) -> tuple[bytes, bytes]:
    truth = make_trajectory(rng, 80)
    reference = write_tum(tmp_path / "gt.txt", truth).read_bytes()
    estimate = write_tum(tmp_path / "est.txt", perturb(truth, rng)).read_bytes()
    return reference, estimate


def test_writes_on_a_full_disk_are_507_and_save_nothing(disk: Path, tmp_path: Path, rng) -> None:
    """POST/PATCH/DELETE on a full disk: 507 naming what to free; after freeing, all works."""
    reference, estimate = _tum(tmp_path, rng)
    # a queue in the data folder that nothing consumes: a queued job stays queued
    with open_api(disk, queue_url="sqlite", min_free_bytes=2 * MB) as api:
        client, headers = api.client, api.headers
        gt = api.upload("gt.txt", reference).json()["id"]
        est = api.upload("est.txt", estimate).json()["id"]
        schedule = client.post("/api/v1/schedules", json=schedule_body(), headers=headers).json()
        assert client.get("/readyz").status_code == 200
        before = _listing(api)
        filler = _fill(disk)
        evaluation = {
            "reference": {"dataset_id": gt},
            "estimates": [{"dataset_id": est}],
            "options": {"formats": ["result.json"]},
        }
        sid = schedule["id"]
        requests: list[tuple[str, str, Any]] = [
            ("POST", "/api/v1/evaluations", evaluation),
            ("POST", "/api/v1/schedules", schedule_body()),
            ("PATCH", f"/api/v1/schedules/{sid}", {"paused": True, "name": "renamed"}),
            ("POST", f"/api/v1/schedules/{sid}/run", None),
            ("POST", f"/api/v1/schedules/{sid}/secret", None),
            ("DELETE", f"/api/v1/schedules/{sid}", None),
            ("DELETE", f"/api/v1/datasets/{est}", None),
        ]
        for method, url, body in requests:
            _assert_storage_full(client.request(method, url, json=body, headers=headers))
        _assert_storage_full(api.upload("again.txt", reference + b"\n"))
        ready = client.get("/readyz")
        assert ready.status_code == 503, ready.text
        assert "LOCEVAL_MIN_FREE_BYTES" in ready.json()["detail"]
        assert client.get(f"/api/v1/datasets/{gt}", headers=headers).status_code == 200
        filler.unlink()
        assert _listing(api) == before  # nothing of the refused requests was saved
        assert client.get("/readyz").status_code == 200
        queued = client.post("/api/v1/evaluations", json=evaluation, headers=headers)
        assert queued.status_code == 202, queued.text
        assert client.delete(f"/api/v1/schedules/{sid}", headers=headers).status_code == 204


def _listing(api: Api) -> dict[str, Any]:
    """What the project holds, as the API lists it."""
    get = api.client.get
    return {
        path: get(f"/api/v1/{path}", headers=api.headers).json()
        for path in ("datasets", "evaluations", "schedules")
    }


def _chunked_form(boundary: str, size: int, seen_free: list[int], disk: Path) -> Iterator[bytes]:
    """A multipart body with a ``size``-byte file, sent in 256 KiB chunks (no length).

    Before each chunk the disk's free space is noted, so the test sees the lowest it fell to.
    """
    yield (
        f'--{boundary}\r\nContent-Disposition: form-data; name="file"; filename="big.bin"\r\n'
        "Content-Type: application/octet-stream\r\n\r\n"
    ).encode()
    chunk = bytes(range(256)) * 1024
    for _ in range(size // len(chunk)):
        seen_free.append(shutil.disk_usage(disk).free)
        yield chunk
    yield f"\r\n--{boundary}--\r\n".encode()


def test_a_chunked_upload_does_not_eat_into_the_reserve(disk: Path) -> None:
    """12 MB without a Content-Length, 12.5 MB free, a 5 MB reserve: 507, nothing kept."""
    reserve = 5 * 1024 * 1024
    with open_api(disk, min_free_bytes=reserve) as api:
        _fill(disk, leave=int(12.5 * 1024 * 1024))
        seen: list[int] = []
        boundary = uuid.uuid4().hex
        answer = api.client.post(
            "/api/v1/datasets",
            content=_chunked_form(boundary, 12 * 1024 * 1024, seen, disk),
            headers={**api.headers, "Content-Type": f"multipart/form-data; boundary={boundary}"},
        )
        _assert_upload_refused(answer)
        assert min(seen) >= reserve - 256 * 1024, (min(seen), reserve)  # one chunk of slack
        assert list((api.data_dir / "incoming").iterdir()) == []
        assert list((api.data_dir / "datasets").iterdir()) == []
        assert shutil.disk_usage(disk).free >= 12 * 1024 * 1024


def _assert_upload_refused(answer: Any) -> None:
    assert answer.status_code == 507, answer.text
    assert answer.headers["content-type"].startswith(PROBLEM_JSON)
    assert answer.json()["type"] == "storage.full"


def test_every_write_route_documents_507(tmp_path: Path) -> None:
    """The OpenAPI document lists 507 for each /api/v1 operation that writes."""
    with open_api(tmp_path) as api:
        paths = api.client.get("/openapi.json").json()["paths"]
    writes = [
        (method, path)
        for path, operations in paths.items()
        if path.startswith("/api/v1/")
        for method in operations
        if method in {"post", "patch", "put", "delete"}
    ]
    assert len(writes) >= 11
    missing = [(m, p) for m, p in writes if "507" not in paths[p][m]["responses"]]
    assert missing == []
