"""A real S3-compatible server for the object-storage tests: SeaweedFS's ``weed``.

One ``weed server`` (:func:`tests.harness.seaweedfs.start_seaweedfs`) runs per test session
on free loopback ports, its data in a temporary folder; each test gets a bucket of its own.
Without the binary the tests are skipped (a failure when CI is set).
"""

from __future__ import annotations

import contextlib
import socket
import threading
from collections.abc import Iterator
from typing import Any

import pytest

from tests.conftest import skip_or_fail
from tests.harness import HarnessUnavailableError
from tests.harness.ports import free_ports
from tests.harness.seaweedfs import CREDENTIALS, SeaweedFS, start_seaweedfs

__all__ = [
    "CREDENTIALS",
    "Gate",
    "GetCounter",
    "SeaweedFS",
    "object_keys",
    "open_multipart_uploads",
]


@pytest.fixture(scope="session")
def seaweedfs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[SeaweedFS]:
    """One SeaweedFS (master, volume, filer, S3) on loopback for the session."""
    pytest.importorskip("boto3", reason="boto3 is the scale extra's S3 client")
    try:
        server = start_seaweedfs(tmp_path_factory.mktemp("seaweedfs"))
    except HarnessUnavailableError as err:
        skip_or_fail(str(err))
        raise  # unreachable: skip_or_fail raised
    except RuntimeError as err:
        pytest.fail(str(err))
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def bucket(seaweedfs: SeaweedFS) -> str:
    """A fresh, empty bucket of its own for one test."""
    return seaweedfs.new_bucket()


@pytest.fixture
def s3_env(seaweedfs: SeaweedFS, monkeypatch: pytest.MonkeyPatch) -> dict[str, str]:
    """The AWS_* variables of the test server, set in this process for the test."""
    env = seaweedfs.env()
    for key, value in env.items():
        monkeypatch.setenv(key, value)
    monkeypatch.delenv("AWS_PROFILE", raising=False)
    return env


def open_multipart_uploads(server: SeaweedFS, bucket: str) -> list[str]:
    """Return the keys of the bucket's multipart uploads that are still open."""
    answer = server.client().list_multipart_uploads(Bucket=bucket)
    return [upload["Key"] for upload in answer.get("Uploads", [])]


def object_keys(server: SeaweedFS, bucket: str, prefix: str = "") -> list[str]:
    """Return the keys of the bucket's objects under ``prefix``."""
    keys: list[str] = []
    for page in (
        server.client().get_paginator("list_objects_v2").paginate(Bucket=bucket, Prefix=prefix)
    ):
        keys.extend(item["Key"] for item in page.get("Contents", []))
    return sorted(keys)


@pytest.fixture(autouse=True)
def _patient_start(monkeypatch: pytest.MonkeyPatch) -> None:
    """Give ``serve``/``worker`` 120 s to start: boto3 adds seconds to a loaded machine's start."""
    monkeypatch.setattr("tests.service.conftest.READY_TIMEOUT_S", 120.0)


class GetCounter:
    """Counts the GETs an S3 client sends and the bytes the store answered them with.

    It wraps the client's HTTP session, through which both boto3's own calls and the ranged
    reads' presigned GETs go (:mod:`service.blobs.ranged`), and reads each answer's
    ``Content-Length`` as the store sent it: an independent count, not the reader's own.
    """

    def __init__(self, client: Any) -> None:
        """Start counting the GETs of ``client``."""
        self.client = client
        session = client._endpoint.http_session  # what boto3 and the ranged reads send through
        send = session.send
        self.calls = 0
        self.bytes = 0

        def counted(request: Any) -> Any:
            answer = send(request)
            if request.method == "GET" and answer.status_code in {200, 206}:
                self.calls += 1
                self.bytes += int(answer.headers.get("content-length", 0))
            return answer

        session.send = counted


class Gate:
    """A TCP relay in front of the S3 gateway that can be shut (an outage) and opened again.

    Shutting it closes its listener and every relayed connection: a client then meets
    refused and reset connections, as when the store's machine or network is gone, while
    the store itself (and every other test's bucket) keeps running.
    """

    def __init__(self, server: SeaweedFS) -> None:
        """Relay a free loopback port to ``server``'s S3 port; open."""
        self._target = int(server.endpoint.rsplit(":", 1)[1])
        self.port = free_ports(1)[0]
        self.endpoint = f"http://127.0.0.1:{self.port}"
        self._listener: socket.socket | None = None
        self._open: set[socket.socket] = set()
        self._lock = threading.Lock()
        self.answered_bytes = 0
        """Bytes the store sent back through the gate (answers: what clients fetched)."""
        self.open()

    def open(self) -> None:
        """Accept and relay connections again."""
        listener = socket.create_server(("127.0.0.1", self.port))
        self._listener = listener
        threading.Thread(target=self._accept, args=(listener,), daemon=True).start()

    def shut(self) -> None:
        """Refuse new connections and cut the relayed ones."""
        listener, self._listener = self._listener, None
        if listener is not None:
            with contextlib.suppress(OSError):
                listener.shutdown(socket.SHUT_RDWR)  # wakes the accept() blocked on it
            listener.close()
        with self._lock:
            for sock in self._open:
                with contextlib.suppress(OSError):
                    sock.shutdown(socket.SHUT_RDWR)
                sock.close()
            self._open.clear()

    def _accept(self, listener: socket.socket) -> None:
        while True:
            try:
                client, _ = listener.accept()
            except OSError:
                return
            try:
                upstream = socket.create_connection(("127.0.0.1", self._target), timeout=10)
            except OSError:
                client.close()
                continue
            upstream.settimeout(None)
            with self._lock:
                self._open.update((client, upstream))
            for source, sink, answers in ((client, upstream, False), (upstream, client, True)):
                threading.Thread(
                    target=self._pump, args=(source, sink), kwargs={"answers": answers}, daemon=True
                ).start()

    def _pump(self, source: socket.socket, sink: socket.socket, *, answers: bool) -> None:
        try:
            while data := source.recv(1 << 16):
                sink.sendall(data)
                if answers:
                    with self._lock:
                        self.answered_bytes += len(data)
        except OSError:
            pass
        finally:
            with contextlib.suppress(OSError):
                sink.shutdown(socket.SHUT_WR)
