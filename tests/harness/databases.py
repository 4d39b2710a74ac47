"""Databases for the service under test: on the machine's servers, or servers of one's own.

- :func:`fresh_database`: a new PostgreSQL database on the machine's server (127.0.0.1:5432),
  dropped afterwards; :func:`empty_redis_database`: a Redis database number nobody uses on the
  machine's server (127.0.0.1:6379), whose loceval keys are deleted afterwards. Neither stops,
  flushes or restarts the shared servers, which other work uses at the same time.
- :class:`OwnPostgres` and :class:`OwnRedis`: servers of one's own on free ports, to stop and
  start at will (the outage tests): a PostgreSQL cluster made by ``initdb`` in a temporary
  folder and run by ``pg_ctl`` (as the ``postgres`` user when run as root, which ``initdb``
  refuses), and a ``redis-server --save ''`` (no persistence: a restart comes back empty).

What the machine lacks raises :class:`~tests.harness.HarnessUnavailableError`.
"""

from __future__ import annotations

import contextlib
import os
import pwd
import secrets
import shutil
import subprocess
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from tests.harness import HarnessUnavailableError
from tests.harness.ports import free_port

__all__ = [
    "SHARED_POSTGRES",
    "SHARED_REDIS",
    "OwnPostgres",
    "OwnRedis",
    "empty_redis_database",
    "fresh_database",
    "postgres_binaries",
]

SHARED_POSTGRES: Final = "host=127.0.0.1 port=5432 user=postgres dbname=test connect_timeout=5"
"""The machine's PostgreSQL, as an administrator connects (trust auth on loopback)."""
SHARED_REDIS: Final = "redis://127.0.0.1:6379"
"""The machine's Redis."""


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
    """Return the folder of ``initdb`` and ``pg_ctl``.

    Raises:
        HarnessUnavailableError: they (or ``redis-server``, needed beside them) are missing.
    """
    if not (PG_BIN / "initdb").is_file() or not (PG_BIN / "pg_ctl").is_file():
        msg = (
            f"PostgreSQL's initdb and pg_ctl are not in {PG_BIN} (install postgresql, or "
            "set LOCEVAL_PG_BIN to their folder)"
        )
        raise HarnessUnavailableError(msg)
    if shutil.which("redis-server") is None:
        msg = "redis-server is not installed (Debian: redis-server)"
        raise HarnessUnavailableError(msg)
    return PG_BIN


def _as_owner() -> list[str]:
    """Return the command prefix that runs PostgreSQL's tools as a non-root user."""
    if os.geteuid() != 0:
        return []
    try:
        pwd.getpwnam("postgres")
    except KeyError:
        msg = "running as root and there is no 'postgres' user to run initdb as"
        raise HarnessUnavailableError(msg) from None
    runuser = shutil.which("runuser")
    if runuser is None:
        msg = "running as root and runuser is missing (initdb refuses root)"
        raise HarnessUnavailableError(msg)
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


@contextlib.contextmanager
def fresh_database(admin: str = SHARED_POSTGRES, *, prefix: str = "loceval_test") -> Iterator[str]:
    """Create a new database on a PostgreSQL server; yield its SQLAlchemy URL; drop it after.

    Args:
        admin: how to connect as an administrator (libpq keywords: host, port, user, dbname).
        prefix: the start of the database's name (a random suffix follows).

    Raises:
        HarnessUnavailableError: the server cannot be reached.
    """
    import psycopg
    from psycopg import sql

    try:
        connection = psycopg.connect(admin, autocommit=True)
    except psycopg.OperationalError as err:
        msg = f"PostgreSQL is not reachable ({admin}): {err}"
        raise HarnessUnavailableError(msg) from None
    name = f"{prefix}_{secrets.token_hex(6)}"
    with connection:
        connection.execute(sql.SQL("CREATE DATABASE {}").format(sql.Identifier(name)))
        info = connection.info
        url = f"postgresql+psycopg://{info.user}@{info.host}:{info.port}/{name}"
    try:
        yield url
    finally:
        with psycopg.connect(admin, autocommit=True) as connection:
            connection.execute(
                sql.SQL("DROP DATABASE IF EXISTS {} WITH (FORCE)").format(sql.Identifier(name))
            )


@contextlib.contextmanager
def empty_redis_database(server: str = SHARED_REDIS) -> Iterator[str]:
    """Yield the URL of a Redis database number (1..15) that holds no key; clean it after.

    Only the keys loceval's queue made are deleted afterwards: the shared server is neither
    flushed nor stopped.

    Raises:
        HarnessUnavailableError: the server cannot be reached, or no number is free.
    """
    import redis

    probe = redis.Redis.from_url(f"{server}/0", socket_timeout=5, socket_connect_timeout=5)
    try:
        probe.ping()
    except redis.RedisError as err:
        msg = f"Redis is not reachable at {server} ({err})"
        raise HarnessUnavailableError(msg) from None
    finally:
        probe.close()
    for number in secrets.SystemRandom().sample(range(1, 16), 15):
        client = redis.Redis.from_url(f"{server}/{number}")
        if client.dbsize() == 0:
            break
        client.close()
    else:
        msg = "every Redis database number 1..15 holds keys; none is free"
        raise HarnessUnavailableError(msg)
    try:
        yield f"{server}/{number}"
    finally:
        keys = list(client.scan_iter(match="*loceval*"))
        if keys:
            client.delete(*keys)
        client.close()
