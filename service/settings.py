"""Service settings, read from ``LOCEVAL_*`` environment variables.

The defaults run everything in one process with nothing installed: SQLite for metadata, a
local folder for uploads and artifacts, and huey's SQLite queue. Scale-out changes settings,
not code: ``LOCEVAL_DATABASE_URL=postgresql+psycopg://...``, ``LOCEVAL_QUEUE_URL=redis://...``
and either a shared ``LOCEVAL_DATA_DIR`` or a bucket, ``LOCEVAL_BLOB_URL=s3://bucket/prefix``.
"""

from __future__ import annotations

import re
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Final
from urllib.parse import urlsplit

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["Settings", "get_settings", "parse_blob_url"]

_REPO = Path(__file__).resolve().parent.parent
_GIB = 1 << 30
_MIN_JOB_MEMORY_MB = 1024
_LOOPBACK_OF_WILDCARD: Final = {"0.0.0.0": "127.0.0.1", "::": "::1", "": "127.0.0.1"}  # noqa: S104
_BUCKET: Final = re.compile(r"[a-z0-9][a-z0-9.\-]{1,61}[a-z0-9]")


def parse_blob_url(url: str) -> tuple[str, str]:
    """Return the bucket and the key prefix (``""`` or ending in ``/``) of an ``s3://`` URL.

    Raises:
        ValueError: not ``s3://BUCKET[/PREFIX]``, or not a valid bucket name.
    """
    match = re.fullmatch(r"s3://([^/]+)(/.*)?", url.strip())
    if match is None or not _BUCKET.fullmatch(match.group(1)):
        msg = (
            "LOCEVAL_BLOB_URL must be s3://BUCKET[/PREFIX] (a bucket name of 3 to 63 "
            f"lower-case letters, digits, '.' and '-'), or empty for the data folder, not {url!r}"
        )
        raise ValueError(msg)
    prefix = (match.group(2) or "").strip("/")
    return match.group(1), f"{prefix}/" if prefix else ""


class Settings(BaseSettings):
    """Everything the service reads from its environment.

    Attributes:
        data_dir: uploads, artifacts, the SQLite database and the SQLite queue live here.
        database_url: SQLAlchemy URL of the metadata database (default: SQLite in data_dir).
        queue_url: ``sqlite`` (huey's SQLite storage in data_dir), ``redis://host:port/db``,
            or ``immediate`` (jobs run inside the request; for tests and debugging only).
        max_upload_bytes: largest accepted upload; bigger ones get 413.
        workers: queue consumer threads in ``serve`` and ``worker``.
        job_attempts: how often an interrupted job is started before it is marked failed.
        job_lease_s: a running job whose heartbeat is older than this is taken as abandoned.
        templates_dir: Jinja2 templates of the reports and the web page.
        public_url: the service's address as users reach it (``https://host/prefix/``):
            every absolute link (``Location``, artifact URLs, webhooks) starts with it; the
            request's ``Host`` and forwarded headers are never used for links. Not set:
            ``http://HOST:PORT`` of ``host`` and ``port`` (see :attr:`resolved_public_url`).
        host: the address ``loceval serve`` listens on when ``--host`` is not given.
        port: the port ``loceval serve`` listens on when ``--port`` is not given.
        webhook_allow: internal webhook targets let through anyway, comma-separated host
            names (``.internal`` for every name under it), addresses and CIDR networks;
            webhooks to loopback, link-local, private and similar addresses are refused
            otherwise (:mod:`service.webhooks`).
        retention_days: finished evaluations (and their artifacts) older than this many days
            are deleted by an hourly sweep; 0 keeps them forever. Datasets are never swept.
        min_free_bytes: free space the data directory keeps: an upload that would leave less
            gets 507, and start-up warns below it; 0 turns the check off.
        job_timeout_s: an evaluation running longer than this is stopped and fails with the
            reason; its worker takes the next job.
        job_memory_mb: the memory (address space, MiB) an evaluation's process may use
            before it fails with the reason, at least 1024 (the loaded libraries take about
            600); 0: no limit.
        blob_url: ``s3://BUCKET[/PREFIX]`` keeps uploads, artifacts and schedule summaries in
            an S3-compatible bucket (endpoint and credentials from ``AWS_ENDPOINT_URL``,
            ``AWS_ACCESS_KEY_ID``, ``AWS_SECRET_ACCESS_KEY``, ``AWS_REGION``); empty keeps
            them in ``data_dir``.
        blob_cache_bytes: with a bucket, the size of each machine's local cache of inputs
            (keyed by content hash, least recently used copies evicted).
        blob_redirect_s: with a bucket, downloads answer 307 to a presigned URL valid this
            many seconds (the client fetches from the store); 0 streams them through the API.
        blob_ranged_bytes: with a bucket, an evaluation reads an MCAP file of at least this
            many bytes where it lies, by ranged reads of its index and the wanted topics'
            messages, instead of copying it into the cache first (unless the cache holds it
            already, or its chunks are compressed); 0 reads every such file so.
        upload_expiry_s: a resumable upload (``/api/v1/uploads``, tus) that receives no
            bytes for this many seconds expires: a sweep every minute removes its parts
            (from the data folder, or its multipart upload from the bucket). Each request
            that writes to it moves its ``Upload-Expires`` on.
    """

    model_config = SettingsConfigDict(env_prefix="LOCEVAL_", extra="ignore")

    data_dir: Path = Path("var")
    database_url: str = ""
    queue_url: str = "sqlite"
    max_upload_bytes: Annotated[int, Field(gt=0)] = 4 * _GIB
    workers: Annotated[int, Field(ge=1, le=64)] = 2
    job_attempts: Annotated[int, Field(ge=1, le=20)] = 3
    job_lease_s: Annotated[float, Field(gt=0)] = 10.0
    templates_dir: Path = _REPO / "templates"
    public_url: str | None = None
    host: Annotated[str, Field(min_length=1)] = "127.0.0.1"
    port: Annotated[int, Field(ge=1, le=65535)] = 8000
    webhook_allow: str = ""
    retention_days: Annotated[int, Field(ge=0, le=36500)] = 0
    min_free_bytes: Annotated[int, Field(ge=0, le=1 << 50)] = _GIB
    job_timeout_s: Annotated[float, Field(gt=0, le=7 * 86400)] = 1800.0
    job_memory_mb: Annotated[int, Field(ge=0, le=1 << 22)] = 4096
    blob_url: str = ""
    blob_cache_bytes: Annotated[int, Field(ge=1 << 20, le=1 << 50)] = 20 * _GIB
    blob_redirect_s: Annotated[int, Field(ge=0, le=7 * 86400)] = 0
    blob_ranged_bytes: Annotated[int, Field(ge=0, le=1 << 50)] = 256 << 20
    upload_expiry_s: Annotated[float, Field(gt=0, le=365 * 86400)] = 86400.0

    @field_validator("blob_url")
    @classmethod
    def _known_blob_url(cls, value: str) -> str:
        if not value.strip():
            return ""
        parse_blob_url(value)  # ValueError says what is wrong
        return value.strip()

    @field_validator("queue_url")
    @classmethod
    def _known_queue(cls, value: str) -> str:
        if value in {"sqlite", "immediate"} or value.startswith(("redis://", "rediss://")):
            return value
        msg = f"LOCEVAL_QUEUE_URL must be sqlite, immediate or redis://HOST:PORT/DB, not {value!r}"
        raise ValueError(msg)

    @field_validator("webhook_allow")
    @classmethod
    def _known_webhook_targets(cls, value: str) -> str:
        from service.webhooks import AllowList  # noqa: PLC0415  (it imports fastapi's errors)

        AllowList.parse(value)  # ValueError names the entry
        return value

    @field_validator("job_memory_mb")
    @classmethod
    def _enough_memory(cls, value: int) -> int:
        if value == 0 or value >= _MIN_JOB_MEMORY_MB:
            return value
        msg = (
            f"LOCEVAL_JOB_MEMORY_MB must be 0 (no limit) or at least {_MIN_JOB_MEMORY_MB}: "
            f"an evaluation's libraries alone take about 600 MiB, not {value}"
        )
        raise ValueError(msg)

    @field_validator("public_url")
    @classmethod
    def _absolute_public_url(cls, value: str | None) -> str | None:
        if value is None:
            return None
        parts = urlsplit(value.strip())
        absolute = parts.scheme in {"http", "https"} and bool(parts.hostname)
        if absolute and not parts.query and not parts.fragment:
            return value.strip()
        msg = (
            "LOCEVAL_PUBLIC_URL must be the service's address as users reach it, "
            f"http(s)://HOST[:PORT][/PREFIX], not {value!r}"
        )
        raise ValueError(msg)

    @property
    def resolved_public_url(self) -> str:
        """The address links start with: ``public_url``, or where ``serve`` listens.

        Without ``LOCEVAL_PUBLIC_URL`` the links follow ``host`` and ``port`` (``loceval
        serve --host/--port`` set them for its process), so ``LOCEVAL_PORT=18731 make serve``
        hands out links to port 18731. An address that listens on every interface
        (``0.0.0.0``, ``::``) is reached as this machine's loopback; behind a proxy or for
        other machines, set ``LOCEVAL_PUBLIC_URL``.
        """
        if self.public_url is not None:
            return self.public_url
        host = _LOOPBACK_OF_WILDCARD.get(self.host, self.host)
        if ":" in host and not host.startswith("["):  # an IPv6 address
            host = f"[{host}]"
        return f"http://{host}:{self.port}"

    @property
    def resolved_database_url(self) -> str:
        """The database URL, defaulting to SQLite inside the data directory."""
        if self.database_url:
            return self.database_url
        return f"sqlite:///{(self.data_dir / 'loceval.db').resolve()}"


@lru_cache
def get_settings() -> Settings:
    """Return the settings of this process (read once)."""
    return Settings()
