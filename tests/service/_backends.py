"""A PostgreSQL and a Redis server of the test's own, on free ports, to stop and start at will.

The outage tests must not touch the machine's shared servers, so they start their own: a
PostgreSQL cluster made by ``initdb`` in a temporary folder and run by ``pg_ctl`` (as the
``postgres`` user when the tests run as root, which ``initdb`` refuses), and a
``redis-server --save ''`` (no persistence: a restart comes back empty). Without the
binaries the tests are skipped with the reason (a failure when CI is set).
"""

from __future__ import annotations

import os
import pwd
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from tests.conftest import skip_or_fail
from tests.service.conftest import free_port

__all__ = ["OwnPostgres", "OwnRedis", "postgres_binaries"]


def _newest_pg_bin() -> Path:
    """Return the newest installed ``/usr/lib/postgresql/N/bin`` (15 if there is none)."""
    found = sorted(
        Path("/usr/lib/postgresql").glob("*/bin"),
        key=lambda p: int(p.parent.name) if p.parent.name.isdigit() else 0,
    )
    return found[-1] if found else Path("/usr/lib/postgresql/15/bin")


PG_BIN: Final = Path(os.environ.get("LOCEVAL_PG_BIN") or _newest_pg_bin())
_START_TIMEOUT_S: Final = 60.0


def postgres_binaries() -> Path:
    """Return the folder of ``initdb`` and ``pg_ctl``, or skip (fail in CI) without them."""
    if not (PG_BIN / "initdb").is_file() or not (PG_BIN / "pg_ctl").is_file():
        skip_or_fail(
            f"PostgreSQL's initdb and pg_ctl are not in {PG_BIN} (install postgresql, or "
            "set LOCEVAL_PG_BIN to their folder)"
        )
    if shutil.which("redis-server") is None:
        skip_or_fail("redis-server is not installed (Debian: redis-server)")
    return PG_BIN


def _as_owner() -> list[str]:
    """Return the command prefix that runs PostgreSQL's tools as a non-root user."""
    if os.geteuid() != 0:
        return []
    try:
        pwd.getpwnam("postgres")
    except KeyError:
        skip_or_fail("running as root and there is no 'postgres' user to run initdb as")
    runuser = shutil.which("runuser")
    if runuser is None:
        skip_or_fail("running as root and runuser is missing (initdb refuses root)")
    return [runuser, "-u", "postgres", "--"]


@dataclass
class OwnPostgres:
    """A PostgreSQL cluster in a temporary folder, on a free loopback port (trust auth)."""

    folder: Path
    port: int

    @classmethod
    def create(cls) -> OwnPostgres:
        """Run initdb in a new folder and start the server."""
        bin_dir = postgres_binaries()
        # Not under pytest's tmp_path: its parents are private to root, the server's user
        # must reach its folder.
        folder = Path(tempfile.mkdtemp(prefix="loceval-pg-"))
        if os.geteuid() == 0:
            owner = pwd.getpwnam("postgres")
            os.chown(folder, owner.pw_uid, owner.pw_gid)
        _run(
            [
                *_as_owner(),
                str(bin_dir / "initdb"),
                "-D",
                str(folder / "data"),
                "-U",
                "postgres",
                "--auth=trust",
                "--no-sync",
            ]
        )
        server = cls(folder, free_port())
        server.start()
        return server

    @property
    def url(self) -> str:
        """The SQLAlchemy URL of the database ``loceval``."""
        return f"postgresql+psycopg://postgres@127.0.0.1:{self.port}/loceval"

    @property
    def dsn(self) -> str:
        """The libpq URL of the database ``loceval`` (for psycopg)."""
        return f"postgresql://postgres@127.0.0.1:{self.port}/loceval?connect_timeout=5"

    def start(self) -> None:
        """Start the server and wait until it accepts connections."""
        options = (
            f"-p {self.port} -k {self.folder} -c listen_addresses=127.0.0.1 "
            "-c fsync=off -c full_page_writes=off"
        )
        _run(
            [
                *_as_owner(),
                str(PG_BIN / "pg_ctl"),
                "start",
                "-w",
                "-t",
                str(int(_START_TIMEOUT_S)),
                "-D",
                str(self.folder / "data"),
                "-l",
                str(self.folder / "server.log"),
                "-o",
                options,
            ]
        )
        self._create_database()

    def stop(self, mode: str = "fast") -> None:
        """Stop the server (``immediate``: as a crash would, without a checkpoint)."""
        _run(
            [
                *_as_owner(),
                str(PG_BIN / "pg_ctl"),
                "stop",
                "-w",
                "-m",
                mode,
                "-D",
                str(self.folder / "data"),
            ]
        )

    def destroy(self) -> None:
        """Stop the server if it runs and remove its folder."""
        subprocess.run(
            [
                *_as_owner(),
                str(PG_BIN / "pg_ctl"),
                "stop",
                "-w",
                "-m",
                "immediate",
                "-D",
                str(self.folder / "data"),
            ],
            capture_output=True,
            check=False,
            timeout=60,
        )
        shutil.rmtree(self.folder, ignore_errors=True)

    def _create_database(self) -> None:
        import psycopg

        admin = f"postgresql://postgres@127.0.0.1:{self.port}/postgres?connect_timeout=5"
        with psycopg.connect(admin, autocommit=True) as connection:
            exists = connection.execute(
                "SELECT 1 FROM pg_database WHERE datname = 'loceval'"
            ).fetchone()
            if exists is None:
                connection.execute("CREATE DATABASE loceval")


@dataclass
class OwnRedis:
    """A ``redis-server`` without persistence on a free loopback port."""

    folder: Path
    port: int
    process: subprocess.Popen[bytes] | None = None

    @classmethod
    def create(cls, folder: Path) -> OwnRedis:
        """Start a server whose (unused) working folder is ``folder``."""
        postgres_binaries()  # the same skip: both servers or none
        server = cls(folder, free_port())
        server.start()
        return server

    @property
    def url(self) -> str:
        """The queue URL (database 0)."""
        return f"redis://127.0.0.1:{self.port}/0"

    def start(self) -> None:
        """Start the server and wait until it answers PING."""
        import redis

        redis_server = shutil.which("redis-server")
        assert redis_server is not None
        self.process = subprocess.Popen(
            [
                redis_server,
                "--port",
                str(self.port),
                "--bind",
                "127.0.0.1",
                "--save",
                "",
                "--appendonly",
                "no",
                "--dir",
                str(self.folder),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        client = redis.Redis.from_url(self.url, socket_connect_timeout=1, socket_timeout=1)
        deadline = time.monotonic() + _START_TIMEOUT_S
        try:
            while True:
                try:
                    client.ping()
                except redis.RedisError:
                    if time.monotonic() > deadline or self.process.poll() is not None:
                        raise
                    time.sleep(0.05)
                else:
                    return
        finally:
            client.close()

    def stop(self) -> None:
        """Stop the server (SIGTERM; with ``--save ''`` it keeps nothing)."""
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            self.process.wait(30)
        self.process = None


def _run(argv: list[str]) -> None:
    """Run a command; fail with its output when it fails."""
    done = subprocess.run(argv, capture_output=True, text=True, check=False, timeout=120)
    if done.returncode != 0:
        msg = f"{' '.join(argv)} exited {done.returncode}:\n{done.stdout}\n{done.stderr}"
        raise RuntimeError(msg)
