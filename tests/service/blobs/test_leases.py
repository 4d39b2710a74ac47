"""Whose upload is abandoned: processes on one host (one host name) keep each other's uploads.

The processes are real: a child Python process opens an upload into the bucket, sends a part
and is then ``kill -9``-ed (or left running). Sweeps by other stores, on the same data folder
or another one, with the same host name, must abort only the uploads of processes that are
gone: at once when a new process takes the gone one's slot in its folder, else once the gone
process's lease in the bucket has lapsed.
"""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import pytest

from loceval.readers.rosbag import HeldMessages
from service.blobs.s3 import PART_BYTES, S3Blobs
from service.blobs.s3upload import held_key
from tests.service.blobs.conftest import SeaweedFS, object_keys, open_multipart_uploads
from tests.service.conftest import REPO

LEASE_S = 4.0  # every store of these tests renews each second and judges after 4 s

_UPLOADER = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from service.blobs.s3 import PART_BYTES, S3Blobs

    url, root, ready, lease_s = sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3]), sys.argv[4]
    store = S3Blobs(url, root, cache_bytes=1 << 30, min_free_bytes=0, lease_s=float(lease_s))
    incoming = store.open_incoming()
    incoming.write(b"x" * (PART_BYTES + 1))  # one part sent: a multipart upload is open
    ready.write_text(incoming.key)
    time.sleep(600)  # until killed
    """
)


def _store(bucket: str, root: Path) -> S3Blobs:
    store = S3Blobs(
        f"s3://{bucket}/lab", root, cache_bytes=1 << 30, min_free_bytes=0, lease_s=LEASE_S
    )
    store.check_bucket()
    return store


def _uploader(bucket: str, root: Path, tmp_path: Path, name: str) -> tuple[Any, str]:
    """Start a child process with an open upload; return it and its upload's key."""
    script = tmp_path / "uploader.py"
    script.write_text(_UPLOADER)
    ready = tmp_path / f"{name}.ready"
    child = subprocess.Popen(
        [sys.executable, str(script), f"s3://{bucket}/lab", str(root), str(ready), str(LEASE_S)],
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    deadline = time.monotonic() + 60
    while not ready.exists():
        assert child.poll() is None, "the uploading process ended before it was ready"
        assert time.monotonic() < deadline, "the uploading process never opened its upload"
        time.sleep(0.05)
    time.sleep(0.05)  # the key is written whole
    return child, ready.read_text()


def _kill(child: Any) -> None:
    child.send_signal(signal.SIGKILL)
    child.wait(10)


@pytest.fixture
def lab(bucket: str, s3_env: dict[str, str]) -> str:
    """A fresh bucket with the test server's AWS_* variables set."""
    del s3_env
    return bucket


def test_a_start_on_the_same_folder_keeps_a_live_process_upload(
    lab: str, seaweedfs: SeaweedFS, tmp_path: Path
) -> None:
    """Two processes on one folder: the second's start keeps the first's upload; once the first
    is killed, the next start takes its slot and aborts its upload at once (no lease wait)."""
    folder = tmp_path / "data"
    first, key = _uploader(lab, folder, tmp_path, "first")
    try:
        second = _store(lab, folder)
        assert second.sweep(startup=True).partial_uploads == 0  # the first one lives
        assert second.instance is not None
        assert second.instance not in key  # a slot of its own: the first holds its one
        own = second.open_incoming()
        own.write(b"y" * (PART_BYTES + 1))
        assert sorted(open_multipart_uploads(seaweedfs, lab)) == sorted(
            [f"lab/{key}", own._full_key]
        )
    finally:
        _kill(first)
    third = _store(lab, folder)
    swept = third.sweep(startup=True)
    assert swept.partial_uploads == 1  # the killed one's, though its lease has not lapsed yet
    assert third.instance is not None
    assert third.instance in key  # it took the gone process's slot
    assert open_multipart_uploads(seaweedfs, lab) == [own._full_key]  # the live one's stays
    own.abort()
    second.close()
    third.close()
    assert object_keys(seaweedfs, lab) == []  # closed stores delete their leases


def test_a_gone_machines_upload_goes_when_its_lease_lapses(
    lab: str, seaweedfs: SeaweedFS, tmp_path: Path
) -> None:
    """Another folder (another machine, same host name): its killed process's upload is kept
    while its lease is fresh and aborted by any sweep once the lease has lapsed."""
    child, key = _uploader(lab, tmp_path / "machine-a", tmp_path, "a")
    sweeper = _store(lab, tmp_path / "machine-b")
    live = sweeper.open_incoming()  # this process's own upload is never another's leftover
    live.write(b"z" * (PART_BYTES + 1))
    try:
        assert sweeper.sweep(older_than_s=0).partial_uploads == 0  # a lease renewed just now
    finally:
        _kill(child)
    assert f"lab/{key}" in open_multipart_uploads(seaweedfs, lab)
    deadline = time.monotonic() + 4 * LEASE_S
    swept = 0
    while not swept and time.monotonic() < deadline:
        time.sleep(0.5)
        swept = sweeper.sweep().partial_uploads
    assert swept == 1
    assert open_multipart_uploads(seaweedfs, lab) == [live._full_key]
    live.abort()
    sweeper.close()


def test_an_upload_completed_but_never_recorded_is_deleted(
    lab: str, seaweedfs: SeaweedFS, tmp_path: Path
) -> None:
    """A process killed between completing an upload and recording its row: the next start on
    its folder deletes the object (not recorded) and keeps a recorded one's object."""
    folder = tmp_path / "data"
    first = _store(lab, folder)
    data = os.urandom(PART_BYTES + 5)
    stored: list[str] = []
    for dataset_id in ("recorded", "lost"):
        incoming = first.open_incoming()
        incoming.write(data)
        incoming.commit()
        incoming.held = HeldMessages({}, {}, {}, set())  # an MCAP upload's, stored beside it
        stored.append(
            first.publish_upload(
                incoming,
                project_id="p",
                dataset_id=dataset_id,
                filename="a.bag",
                sha256=hashlib.sha256(data).hexdigest(),
            )
        )
    # "killed" before either marker was settled: the slot and the lease are let go
    first._slot.close()  # type: ignore[union-attr]
    first._slot = None
    first._lease.stop()  # type: ignore[union-attr]
    restarted = _store(lab, folder)
    asked: list[list[str]] = []
    swept = restarted.sweep(lambda ids: asked.append(ids) or set(ids) & {"recorded"}, startup=True)
    assert (swept.partial_uploads, swept.datasets) == (0, 1)
    assert sorted(asked) == [["lost"], ["recorded"]]
    assert restarted.exists(stored[0])
    assert not restarted.exists(stored[1])
    assert [k for k in object_keys(seaweedfs, lab) if "/pending/" in k] == []
    assert restarted.exists(held_key(stored[0]))  # the held messages go with their upload
    assert not restarted.exists(held_key(stored[1]))
    restarted.close()
