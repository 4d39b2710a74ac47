"""The object-storage backend: blobs in an S3-compatible bucket (``LOCEVAL_BLOB_URL=s3://...``).

Layout under the URL's prefix (keys relative to it are the database's storage paths)::

    incoming/<host>/<uuid>                an upload being received (a multipart upload)
    datasets/<project id>/<sha256>        a stored upload, addressed by its content
    evaluations/<id>/artifacts/<name>     an evaluation's artifacts
    runs/<run id>/artifacts/<name>        a schedule run's summary report

An upload streams into a multipart upload part by part (a few parts in flight, never the
whole file in memory or on disk); it becomes an object only when complete, is then copied to
its content-addressed key (where identical bytes of the project already are, nothing is
copied) and deleted. A failed or interrupted upload is aborted; the API's start (for its own
host's uploads) and the hourly sweep (for any older than an hour) abort what a crash left.

The endpoint and credentials come from the environment as every S3 client takes them
(``AWS_ENDPOINT_URL``, ``AWS_ACCESS_KEY_ID``, ``AWS_SECRET_ACCESS_KEY``, ``AWS_REGION``);
boto3 speaks the protocol.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import os
import re
import shutil
import socket
import uuid
from collections.abc import Callable, Iterable, Iterator, Mapping
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import boto3
from boto3.s3.transfer import TransferConfig
from botocore.config import Config
from botocore.exceptions import BotoCoreError, ClientError
from starlette.responses import RedirectResponse, Response, StreamingResponse

from service.blobs.base import STALE_UPLOAD_S, Blobs, Incoming, artifact_key, parse_blob_url
from service.blobs.cache import InputCache
from service.errors import ServiceUnavailableError, StartupError, register_private_root
from service.storage import Swept

if TYPE_CHECKING:
    from mypy_boto3_s3 import S3Client
    from mypy_boto3_s3.type_defs import CopySourceTypeDef, ObjectIdentifierTypeDef

__all__ = ["PART_BYTES", "S3Blobs", "S3Incoming", "make_client", "store_errors"]

PART_BYTES: Final = 8 << 20
"""The size of an upload's parts (S3 wants at least 5 MiB but for the last)."""
_IN_FLIGHT: Final = 4  # parts sent at once: the upload holds at most this many in memory
_COPY_LIMIT: Final = 5 << 30  # CopyObject's limit; above it the managed copy goes by parts
_DOWNLOAD_CHUNK: Final = 1 << 20
_TRANSFER: Final = TransferConfig(
    multipart_threshold=64 << 20, multipart_chunksize=8 << 20, max_concurrency=4
)


@contextlib.contextmanager
def store_errors() -> Iterator[None]:
    """Raise ServiceUnavailableError when the object store fails (unreachable, refusing)."""
    try:
        yield
    except (BotoCoreError, ClientError) as err:
        code = err.response.get("Error", {}).get("Code", "") if isinstance(err, ClientError) else ""
        msg = (
            f"The object store cannot be used ({type(err).__name__}{' ' + code if code else ''}); "
            "try again in a minute (GET /readyz shows when it is back)."
        )
        raise ServiceUnavailableError(msg) from err


def _missing(err: ClientError) -> bool:
    return err.response.get("Error", {}).get("Code") in {"404", "NoSuchKey", "NotFound"}


def make_client(*, pool: int = 32) -> S3Client:
    """Return an S3 client configured from the conventional ``AWS_*`` variables."""
    endpoint = os.environ.get("AWS_ENDPOINT_URL") or None
    config = Config(
        max_pool_connections=pool,
        retries={"max_attempts": 5, "mode": "standard"},
        s3={"addressing_style": "path" if endpoint else "auto"},
        # S3-compatible stores do not all know the newer default checksums
        request_checksum_calculation="when_required",
        response_checksum_validation="when_required",
        connect_timeout=10,
        read_timeout=120,
    )
    region = os.environ.get("AWS_REGION") or os.environ.get("AWS_DEFAULT_REGION") or "us-east-1"
    client: S3Client = boto3.session.Session().client(
        "s3", endpoint_url=endpoint, region_name=region, config=config
    )
    return client


class S3Incoming(Incoming):
    """An upload streamed into a multipart upload, at most a few parts in memory."""

    def __init__(self, store: S3Blobs, key: str) -> None:
        """Receive into ``key`` (relative to the prefix); nothing is sent before a part is full."""
        super().__init__()
        self.store = store
        self.key = key  # relative to the prefix
        self._buffer = bytearray()
        self._upload_id: str | None = None
        self._parts: list[tuple[int, Future[str]]] = []
        self._pool: ThreadPoolExecutor | None = None
        self.committed = False
        self.done = False

    @property
    def _full_key(self) -> str:
        return self.store.prefix + self.key

    def _write(self, chunk: bytes) -> None:
        self._buffer += chunk
        while len(self._buffer) >= PART_BYTES:
            self._send(bytes(self._buffer[:PART_BYTES]))
            del self._buffer[:PART_BYTES]

    def _send(self, data: bytes) -> None:
        client = self.store.client
        if self._upload_id is None:
            with store_errors():
                created = client.create_multipart_upload(
                    Bucket=self.store.bucket, Key=self._full_key
                )
            self._upload_id = created["UploadId"]
            self._pool = ThreadPoolExecutor(_IN_FLIGHT, thread_name_prefix="loceval-upload")
        pending = [f for _, f in self._parts if not f.done()]
        if len(pending) >= _IN_FLIGHT:
            wait(pending, return_when=FIRST_COMPLETED)
        for _, future in self._parts:
            if future.done():
                future.result()  # a failed part fails the upload now
        number = len(self._parts) + 1
        assert self._pool is not None  # noqa: S101  (created with the upload id)
        self._parts.append((number, self._pool.submit(self._upload_part, number, data)))

    def _upload_part(self, number: int, data: bytes) -> str:
        assert self._upload_id is not None  # noqa: S101
        with store_errors():
            answer = self.store.client.upload_part(
                Bucket=self.store.bucket,
                Key=self._full_key,
                UploadId=self._upload_id,
                PartNumber=number,
                Body=data,
            )
        return answer["ETag"]

    def commit(self) -> None:
        """See :meth:`Incoming.commit`."""
        if self.committed:
            return
        client = self.store.client
        if self._upload_id is None:  # smaller than one part: one request
            with store_errors():
                client.put_object(
                    Bucket=self.store.bucket, Key=self._full_key, Body=bytes(self._buffer)
                )
        else:
            if self._buffer:
                self._send(bytes(self._buffer))
            parts = [{"PartNumber": n, "ETag": f.result()} for n, f in self._parts]
            with store_errors():
                client.complete_multipart_upload(
                    Bucket=self.store.bucket,
                    Key=self._full_key,
                    UploadId=self._upload_id,
                    MultipartUpload={"Parts": parts},  # type: ignore[typeddict-item]
                )
            self._close_pool()
        self._buffer = bytearray()
        self.committed = True

    def _close_pool(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def abort(self) -> None:
        """See :meth:`Incoming.abort`."""
        if self.done:
            return
        self.done = True
        self._buffer = bytearray()
        self._close_pool()
        client = self.store.client
        with contextlib.suppress(BotoCoreError, ClientError):  # the sweep takes what stays
            if self.committed:
                client.delete_object(Bucket=self.store.bucket, Key=self._full_key)
            elif self._upload_id is not None:
                client.abort_multipart_upload(
                    Bucket=self.store.bucket, Key=self._full_key, UploadId=self._upload_id
                )


class S3Blobs(Blobs):
    """Blobs in a bucket; local copies of inputs in a bounded cache under ``root/cache``.

    Args:
        url: ``s3://BUCKET[/PREFIX]``.
        root: the local data folder (cache, staging folders, SQLite files if used).
        cache_bytes: the input cache's size.
        min_free_bytes: the local disk's reserve (the cache keeps it).
        redirect_s: downloads answer 307 to a presigned URL valid this long; 0 streams.
        client: the S3 client (default: from the ``AWS_*`` environment variables).
    """

    kind = "s3"

    def __init__(
        self,
        url: str,
        root: Path,
        *,
        cache_bytes: int,
        min_free_bytes: int,
        redirect_s: int = 0,
        client: S3Client | None = None,
    ) -> None:
        """Connect to the bucket (checked by :meth:`check_bucket`)."""
        self.bucket, self.prefix = parse_blob_url(url)
        self.root = root.resolve()
        self.client = client or make_client()
        self.redirect_s = redirect_s
        self.host = _host_label()
        self.cache = InputCache(
            self.root / "cache", max_bytes=cache_bytes, min_free_bytes=min_free_bytes
        )
        self.staging = self.root / "staging"
        register_private_root(self.root)  # problem documents never show it

    @property
    def description(self) -> str:
        """See :meth:`Blobs.description`."""
        endpoint = os.environ.get("AWS_ENDPOINT_URL") or "AWS"
        return f"blobs in s3://{self.bucket}/{self.prefix} at {endpoint}"

    def check_bucket(self) -> None:
        """Refuse to start when the bucket cannot be reached or does not exist.

        Raises:
            StartupError: the message names the bucket, the endpoint and what to check.
        """
        try:
            self.client.head_bucket(Bucket=self.bucket)
        except (BotoCoreError, ClientError) as err:
            code = (
                err.response.get("Error", {}).get("Code", "")
                if isinstance(err, ClientError)
                else ""
            )
            endpoint = os.environ.get("AWS_ENDPOINT_URL") or "AWS's default endpoint"
            msg = (
                f"The bucket {self.bucket!r} at {endpoint} cannot be used "
                f"({type(err).__name__}{' ' + code if code else ''}); create it, or check "
                "AWS_ENDPOINT_URL, AWS_ACCESS_KEY_ID, AWS_SECRET_ACCESS_KEY and LOCEVAL_BLOB_URL."
            )
            raise StartupError(msg) from None

    # -- uploads ---------------------------------------------------------------------------

    def open_incoming(self) -> S3Incoming:
        """See :meth:`Blobs.open_incoming`."""
        return S3Incoming(self, f"incoming/{self.host}/{uuid.uuid4().hex}")

    def publish_upload(
        self, incoming: Incoming, *, project_id: str, dataset_id: str, filename: str, sha256: str
    ) -> str:
        """See :meth:`Blobs.publish_upload`."""
        del dataset_id, filename  # addressed by content: the row keeps the name
        if not isinstance(incoming, S3Incoming) or not incoming.committed:
            msg = "only a committed upload to the bucket can be published in it"
            raise TypeError(msg)
        key = f"datasets/{project_id}/{sha256}"
        if not self.exists(key):
            source: CopySourceTypeDef = {"Bucket": self.bucket, "Key": self.prefix + incoming.key}
            with store_errors():
                size = self.client.head_object(Bucket=self.bucket, Key=source["Key"])[
                    "ContentLength"
                ]
                if size < _COPY_LIMIT:
                    self.client.copy_object(
                        CopySource=source, Bucket=self.bucket, Key=self.prefix + key
                    )
                else:
                    self.client.copy(source, self.bucket, self.prefix + key, Config=_TRANSFER)
        incoming.abort()  # the received copy goes
        return key

    def remove_upload(self, dataset_id: str, storage_path: str) -> None:
        """See :meth:`Blobs.remove_upload`."""
        del dataset_id
        with store_errors():
            self.client.delete_object(Bucket=self.bucket, Key=self.prefix + storage_path)

    def check_free_space(self, min_free_bytes: int, *, incoming_bytes: int = 0) -> bool:
        """See :meth:`Blobs.check_free_space`."""
        del min_free_bytes, incoming_bytes  # uploads touch no local disk; a bucket has no "free"
        return True

    # -- inputs ----------------------------------------------------------------------------

    def local_path(self, storage_path: str, *, filename: str, sha256: str) -> Path:
        """See :meth:`Blobs.local_path`."""
        key = self.prefix + storage_path
        with store_errors():
            size = self.client.head_object(Bucket=self.bucket, Key=key)["ContentLength"]

        def download(target: Path) -> None:
            with store_errors():
                self.client.download_file(self.bucket, key, str(target), Config=_TRANSFER)

        return self.cache.fetch(sha256, filename, size, download)

    def pinned(self) -> contextlib.AbstractContextManager[None]:
        """See :meth:`Blobs.pinned`."""
        return self.cache.pinned()

    # -- job artifacts ---------------------------------------------------------------------

    def job_staging_dir(self, folder: str, job_id: str) -> Path:
        """See :meth:`Blobs.job_staging_dir`."""
        parent = self.staging / folder / job_id
        parent.mkdir(parents=True, exist_ok=True)
        return parent / f".staging-{uuid.uuid4().hex}"

    def publish_job_artifacts(self, folder: str, job_id: str, staging: Path) -> Path:
        """See :meth:`Blobs.publish_job_artifacts`."""
        self._delete_prefix(f"{folder}/{job_id}/artifacts/")
        for path in sorted(p for p in staging.rglob("*") if p.is_file()):
            key = f"{self.prefix}{folder}/{job_id}/artifacts/{path.relative_to(staging).as_posix()}"
            with store_errors():
                self.client.upload_file(str(path), self.bucket, key, Config=_TRANSFER)
        return staging

    def publish_job_artifact(self, folder: str, job_id: str, name: str, path: Path) -> None:
        """See :meth:`Blobs.publish_job_artifact`."""
        key = f"{self.prefix}{artifact_key(folder, job_id, name)}"
        with store_errors():
            self.client.upload_file(str(path), self.bucket, key, Config=_TRANSFER)

    def clear_job(self, folder: str, job_id: str) -> None:
        """See :meth:`Blobs.clear_job`."""
        self.remove_job(folder, job_id)

    def remove_job(self, folder: str, job_id: str) -> None:
        """See :meth:`Blobs.remove_job`."""
        shutil.rmtree(self.staging / folder / job_id, ignore_errors=True)
        self._delete_prefix(f"{folder}/{job_id}/")

    def job_ids(self, folder: str) -> Mapping[str, float]:
        """See :meth:`Blobs.job_ids`."""
        found: dict[str, float] = {}
        for item in self._list(f"{folder}/"):
            job_id = item["Key"][len(self.prefix) + len(folder) + 1 :].split("/", 1)[0]
            found[job_id] = max(found.get(job_id, 0.0), item["LastModified"].timestamp())
        return found

    # -- reading back ----------------------------------------------------------------------

    def exists(self, key: str) -> bool:
        """See :meth:`Blobs.exists`."""
        return self.size(key) is not None

    def size(self, key: str) -> int | None:
        """Return a blob's size in bytes, or None when there is no such blob."""
        try:
            head = self.client.head_object(Bucket=self.bucket, Key=self.prefix + key)
        except ClientError as err:
            if _missing(err):
                return None
            with store_errors():
                raise
        except BotoCoreError:
            with store_errors():
                raise
        return int(head["ContentLength"])

    def read_bytes(self, key: str) -> bytes:
        """See :meth:`Blobs.read_bytes`."""
        with store_errors():
            body = self.client.get_object(Bucket=self.bucket, Key=self.prefix + key)["Body"]
            return body.read()

    def response(self, key: str, *, media_type: str, filename: str, inline: bool) -> Response:
        """See :meth:`Blobs.response`."""
        disposition = f'{"inline" if inline else "attachment"}; filename="{filename}"'
        if self.redirect_s:
            with store_errors():
                url = self.client.generate_presigned_url(
                    "get_object",
                    Params={
                        "Bucket": self.bucket,
                        "Key": self.prefix + key,
                        "ResponseContentType": media_type,
                        "ResponseContentDisposition": disposition,
                    },
                    ExpiresIn=self.redirect_s,
                )
            return RedirectResponse(url, status_code=307)
        with store_errors():
            answer = self.client.get_object(Bucket=self.bucket, Key=self.prefix + key)
        headers = {
            "content-length": str(answer["ContentLength"]),
            "content-disposition": disposition,
        }
        return StreamingResponse(
            answer["Body"].iter_chunks(_DOWNLOAD_CHUNK), media_type=media_type, headers=headers
        )

    # -- upkeep ----------------------------------------------------------------------------

    def sweep(
        self,
        recorded: Callable[[list[str]], Iterable[str]] = lambda _ids: (),
        *,
        older_than_s: float = STALE_UPLOAD_S,
        startup: bool = False,
    ) -> Swept:
        """See :meth:`Blobs.sweep` (a bucket's datasets are addressed by content: kept)."""
        del recorded
        cutoff = dt.datetime.now(dt.UTC) - dt.timedelta(seconds=older_than_s)
        own = f"{self.prefix}incoming/{self.host}/"
        removed = 0
        with store_errors():
            paginator = self.client.get_paginator("list_multipart_uploads")
            for page in paginator.paginate(Bucket=self.bucket, Prefix=f"{self.prefix}incoming/"):
                for upload in page.get("Uploads", []):
                    key = upload["Key"]
                    if upload["Initiated"] < cutoff or (startup and key.startswith(own)):
                        with contextlib.suppress(ClientError):  # finished meanwhile
                            self.client.abort_multipart_upload(
                                Bucket=self.bucket, Key=key, UploadId=upload["UploadId"]
                            )
                        removed += 1
            for item in self._list("incoming/"):
                key = item["Key"]
                if item["LastModified"] < cutoff or (startup and key.startswith(own)):
                    self.client.delete_object(Bucket=self.bucket, Key=key)
                    removed += 1
        return Swept(partial_uploads=removed)

    def cached_bytes(self) -> int:
        """See :meth:`Blobs.cached_bytes`."""
        return self.cache.size()

    def ping(self) -> None:
        """See :meth:`Blobs.ping`."""
        with store_errors():
            self.client.head_bucket(Bucket=self.bucket)

    # -- helpers ---------------------------------------------------------------------------

    def _list(self, relative: str) -> Iterator[Any]:
        with store_errors():
            paginator = self.client.get_paginator("list_objects_v2")
            for page in paginator.paginate(Bucket=self.bucket, Prefix=self.prefix + relative):
                yield from page.get("Contents", [])

    def _delete_prefix(self, relative: str) -> None:
        keys = [item["Key"] for item in self._list(relative)]
        for start in range(0, len(keys), 1000):
            batch: list[ObjectIdentifierTypeDef] = [{"Key": k} for k in keys[start : start + 1000]]
            with store_errors():
                self.client.delete_objects(
                    Bucket=self.bucket, Delete={"Objects": batch, "Quiet": True}
                )


def _host_label() -> str:
    """Return this machine's name as a key segment (its uploads' folder in ``incoming/``)."""
    return re.sub(r"[^A-Za-z0-9.\-]", "_", socket.gethostname())[:63] or "host"
