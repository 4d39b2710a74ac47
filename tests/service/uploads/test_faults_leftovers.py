"""Leftovers of killed processes are swept: partial uploads and datasets never recorded.

Each process that opens the data folder holds a lock on its own file under ``owners/``; the
kernel drops it when the process dies, so a sweep knows at once which owners are gone. The
crashes here are real ``kill -9`` of real processes: a ``loceval serve`` in the middle of
an upload, and a process that published an upload and was killed while inspecting it.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import textwrap
import time
import uuid
from pathlib import Path
from urllib.parse import urlsplit

from service.blobs.local import LocalBlobs
from tests.factories import make_trajectory, write_tum
from tests.service._api_fixtures import open_api
from tests.service.conftest import REPO, start_server

TIMEOUT_S = 60.0


def _wait_for(condition, what: str, timeout: float = TIMEOUT_S) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


def _parts(data_dir: Path) -> list[Path]:
    return sorted((data_dir / "incoming").glob("*.part"))


def test_a_killed_servers_partial_uploads_go_at_its_next_start(tmp_path: Path) -> None:
    """``kill -9`` of ``loceval serve`` mid-upload; the next start removes the part at once."""
    data_dir = tmp_path / "data"
    server = start_server(data_dir)
    address = urlsplit(server.url)
    boundary = uuid.uuid4().hex
    head = (
        f"POST /api/v1/datasets HTTP/1.1\r\nHost: {address.netloc}\r\n"
        f"Authorization: Bearer {server.api_key}\r\n"
        f"Content-Type: multipart/form-data; boundary={boundary}\r\n"
        "Transfer-Encoding: chunked\r\n\r\n"
    ).encode()
    part = (
        f'--{boundary}\r\nContent-Disposition: form-data; name="file"; filename="run.txt"\r\n\r\n'
    ).encode() + b"0 0 0 0\n" * 500_000  # 4 MB of a file whose end never comes
    try:
        with socket.create_connection((address.hostname, address.port), timeout=30) as sock:
            sock.sendall(head + b"%x\r\n%s\r\n" % (len(part), part))
            _wait_for(
                lambda: any(p.stat().st_size > 1_000_000 for p in _parts(data_dir)),
                "the upload to reach the disk",
            )
            server.kill()
    finally:
        server.stop()
    (left,) = _parts(data_dir)
    assert left.stat().st_size > 1_000_000
    restarted = start_server(data_dir, api_key=server.api_key)
    try:
        assert _parts(data_dir) == []  # gone by the time the server answers /readyz
        assert [p.name for p in (data_dir / "owners").glob("*.lock")] == [
            f"{restarted_owner(data_dir)}.lock"
        ]
        with restarted.client() as client:
            assert client.get("/api/v1/datasets").json()["count"] == 0
    finally:
        restarted.stop()


def restarted_owner(data_dir: Path) -> str:
    """The owner id of the one process that holds its lock in ``data_dir``."""
    (lock,) = (data_dir / "owners").glob("*.lock")
    return lock.name.removesuffix(".lock")


_CRASHING_UPLOAD = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from service.uploads import datasets
    from service.auth import create_key
    from service.jobs.queue import create_runtime
    from service.settings import Settings
    from service.uploads.multipart import ReceivedFile

    data_dir, source, sha256 = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3]
    ready = Path(sys.argv[4])
    runtime = create_runtime(Settings(data_dir=data_dir, queue_url="immediate"))
    with runtime.sessions() as session:
        create_key(session, "crashing")
    project = session.scalar(__import__("sqlalchemy").text("SELECT id FROM projects"))

    def inspect_upload(path, filename):
        ready.write_text(str(path))  # published: now the test kills this process
        time.sleep(600)

    datasets.inspect_upload = inspect_upload  # the inspection of a big bag takes minutes
    incoming = runtime.store.open_incoming()  # as the multipart receiver writes it
    data = source.read_bytes()
    incoming.write(data)
    incoming.commit()
    received = ReceivedFile("file", source.name, incoming, len(data), sha256)
    datasets.store_upload(runtime, project, received)
    """
)


def test_a_dataset_killed_during_inspection_is_removed_and_uploads_again_once(
    tmp_path: Path, rng
) -> None:
    """A process killed between publishing an upload and recording it leaves no orphan."""
    import hashlib

    source = write_tum(tmp_path / "run.txt", make_trajectory(rng, 50))
    content = source.read_bytes()
    data_dir = tmp_path / "data"
    ready = tmp_path / "published"
    script = tmp_path / "crash.py"
    script.write_text(_CRASHING_UPLOAD)
    sha256 = hashlib.sha256(content).hexdigest()
    child = subprocess.Popen(
        [sys.executable, str(script), str(data_dir), str(source), sha256, str(ready)],
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    try:
        _wait_for(lambda: ready.exists() or child.poll() is not None, "the publish")
        assert child.poll() is None, "the uploading process ended before it was killed"
        child.kill()
        child.wait(10)
    finally:
        if child.poll() is None:
            child.kill()
    (orphan,) = (data_dir / "datasets").iterdir()
    assert Path(ready.read_text()).is_relative_to(orphan)
    with open_api(tmp_path) as api:  # the app's start sweeps
        assert list((data_dir / "datasets").iterdir()) == []
        again = api.upload("run.txt", content)
        assert again.status_code == 201, again.text
        assert [p.name for p in (data_dir / "datasets").iterdir()] == [again.json()["id"]]
        assert api.client.get("/api/v1/datasets", headers=api.headers).json()["count"] == 1


_OWNER = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from service.blobs.local import LocalBlobs

    store = LocalBlobs(Path(sys.argv[1]))
    part = store.new_incoming()
    part.write_bytes(b"half an upload")
    with store.publishing(sys.argv[2]):
        folder = store.datasets / sys.argv[2]
        folder.mkdir()
        (folder / "run.bag").write_bytes(b"#ROSBAG V2.0")
        Path(sys.argv[3]).write_text(str(part))
        time.sleep(600)
    """
)


def test_a_dead_owners_leftovers_go_at_once_a_live_ones_stay(tmp_path: Path) -> None:
    """Several processes share a folder: a sweep removes what a killed one left, not more."""
    data_dir = tmp_path / "data"
    store = LocalBlobs(data_dir)
    mine = store.new_incoming()
    mine.write_bytes(b"mine, still arriving")
    legacy = data_dir / "incoming" / f"{uuid.uuid4().hex}.part"  # an older version's name
    legacy.write_bytes(b"whose?")
    script = tmp_path / "owner.py"
    script.write_text(_OWNER)
    dataset_id = str(uuid.uuid4())
    ready = tmp_path / "ready"
    child = subprocess.Popen(
        [sys.executable, str(script), str(data_dir), dataset_id, str(ready)],
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    try:
        _wait_for(lambda: ready.exists() or child.poll() is not None, "the other owner")
        assert child.poll() is None
        theirs = Path(ready.read_text())
        swept = store.sweep(lambda _ids: [])
        assert (swept.partial_uploads, swept.datasets) == (0, 0)  # it lives: all is kept
        assert theirs.exists()
        assert (store.datasets / dataset_id).is_dir()
        child.kill()
        child.wait(10)
        swept = store.sweep(lambda _ids: [])  # no hour's wait: the owner is known gone
        assert (swept.partial_uploads, swept.datasets) == (1, 1)
        assert not theirs.exists()
        assert not (store.datasets / dataset_id).exists()
        assert mine.exists()
        assert legacy.exists()  # without an owner: only once it is an hour old
        assert sorted(p.name for p in store.owners.iterdir()) == [f"{store.owner}.lock"]
        old = time.time() - 7200
        os.utime(legacy, (old, old))
        assert store.sweep().partial_uploads == 1
        assert not legacy.exists()
    finally:
        if child.poll() is None:
            child.kill()
        store.close()


def test_a_recorded_dataset_is_kept_when_its_publisher_dies_after_the_row(tmp_path: Path) -> None:
    """Killed after the row was committed (the marker still there): the folder stays."""
    data_dir = tmp_path / "data"
    script = tmp_path / "owner.py"
    script.write_text(_OWNER)
    dataset_id = str(uuid.uuid4())
    ready = tmp_path / "ready"
    child = subprocess.Popen(
        [sys.executable, str(script), str(data_dir), dataset_id, str(ready)],
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    try:
        _wait_for(lambda: ready.exists() or child.poll() is not None, "the other owner")
        child.kill()
        child.wait(10)
    finally:
        if child.poll() is None:
            child.kill()
    store = LocalBlobs(data_dir)
    try:
        asked: list[list[str]] = []
        swept = store.sweep(lambda ids: asked.append(ids) or ids)
        assert asked == [[dataset_id]]
        assert swept.datasets == 0
        assert (store.datasets / dataset_id / "run.bag").exists()
        assert list(store.owners.glob("*.publishing")) == []
    finally:
        store.close()
