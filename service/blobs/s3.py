"""The object-storage backend: blobs in an S3-compatible bucket (``LOCEVAL_BLOB_URL=s3://...``).

Layout under the URL's prefix (keys relative to it are the database's storage paths)::

    uploads/<instance>/<uuid>             an upload: a multipart upload while it is received,
                                          then, completed in place, the dataset's object
    pending/<instance>/<uuid>             an upload completed but not yet recorded (holds the
                                          dataset id; gone once the row is committed)
    held/<instance>/<uuid>                an MCAP upload's tf and pose messages, kept as it
                                          streamed through (an evaluation's one request)
    instances/<instance>                  the lease of a live process that receives uploads
    datasets/<project id>/<sha256>        a dataset moved in by ``loceval storage migrate``
    evaluations/<id>/artifacts/<name>     an evaluation's artifacts
    runs/<run id>/artifacts/<name>        a schedule run's summary report

An upload streams into a multipart upload part by part (a few parts in flight, never the
whole file in memory or on disk), hashed on the way. It is never copied: once received, the
database is asked whether the project has these bytes already (then the multipart upload is
aborted, and no object ever existed), else it is completed where it was received, and the
whole object appears at once. A failed or interrupted upload is aborted. What a crash leaves
is found by its *instance* (:mod:`service.blobs.lease`): the start of a process on the same
data folder takes the gone process's identity and sweeps its leftovers at once; any sweep
(every minute in the workers) takes those of processes whose lease in the bucket lapsed. A
live process's uploads are never touched, whatever its host name.

The endpoint and credentials come from the environment as every S3 client takes them
(``AWS_ENDPOINT_URL``, ``AWS_ACCESS_KEY_ID``, ``AWS_SECRET_ACCESS_KEY``, ``AWS_REGION``);
boto3 speaks the protocol.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import email.utils
import os
import shutil
import threading
import uuid
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path, PurePosixPath
from typing import IO, TYPE_CHECKING, Any, Final

from boto3.s3.transfer import TransferConfig
from botocore.exceptions import BotoCoreError, ClientError

from service.blobs.base import (
    STALE_UPLOAD_S,
    Blobs,
    Download,
    Incoming,
    Redirect,
    Stream,
    Swept,
    artifact_key,
    content_disposition,
)
from service.blobs.cache import InputCache
from service.blobs.lease import LEASE_S, Lease, claim_slot
from service.blobs.ranged import ObjectFile
from service.blobs.s3client import make_client, store_errors, unless_missing
from service.blobs.s3upload import (
    PART_BYTES,
    UPLOAD_PREFIXES,
    S3Incoming,
    held_key,
    pending_key,
)
from service.errors import StartupError
from service.settings import Settings, parse_blob_url

if TYPE_CHECKING:
    from mypy_boto3_s3 import S3Client
    from mypy_boto3_s3.type_defs import ObjectIdentifierTypeDef


__all__ = [
    "PART_BYTES",
    "RANGED_INPUT_BYTES",
    "S3Blobs",
    "S3Incoming",
    "make_client",
    "store_errors",
]

RANGED_INPUT_BYTES: Final[int] = Settings.model_fields["blob_ranged_bytes"].default
"""The default size from which an evaluation reads a bag in the bucket by ranged reads
(``LOCEVAL_BLOB_RANGED_BYTES``'s default: one figure, in the settings)."""
_DOWNLOAD_CHUNK: Final = 1 << 20
_TRANSFER: Final = TransferConfig(
    multipart_threshold=64 << 20, multipart_chunksize=8 << 20, max_concurrency=4
)


class S3Blobs(Blobs):
    """Blobs in a bucket; local copies of inputs in a bounded cache under ``root/cache``.

    Args:
        url: ``s3://BUCKET[/PREFIX]``.
        root: the local data folder (cache, staging folders, SQLite files if used).
        cache_bytes: the input cache's size.
        min_free_bytes: the local disk's reserve (the cache keeps it).
        redirect_s: downloads answer 307 to a presigned URL valid this long; 0 streams.
        ranged_bytes: evaluations read MCAP files and ROS 1 bags at least this large by
            ranged reads where they lie, unless the cache holds a copy (:meth:`job_input`).
        client: the S3 client (default: from the ``AWS_*`` environment variables).
        lease_s: an uploading process whose lease is older than this is gone.
    """

    kind = "s3"
    reads_in_place = True

    def __init__(
        self,
        url: str,
        root: Path,
        *,
        cache_bytes: int,
        min_free_bytes: int,
        redirect_s: int = 0,
        ranged_bytes: int = RANGED_INPUT_BYTES,
        client: S3Client | None = None,
        lease_s: float = LEASE_S,
    ) -> None:
        """Connect to the bucket (checked by :meth:`check_bucket`)."""
        self.bucket, self.prefix = parse_blob_url(url)
        self.root = root.resolve()
        self.client = client or make_client()
        self.redirect_s = redirect_s
        self.ranged_bytes = ranged_bytes
        self.lease_s = lease_s
        self.instance: str | None = None
        """This process's instance id once it receives uploads (:mod:`service.blobs.lease`)."""
        self._slot: IO[bytes] | None = None
        self._lease: Lease | None = None
        self._instance_lock = threading.Lock()
        self._publishing: dict[str, S3Incoming] = {}
        self.cache = InputCache(
            self.root / "cache", max_bytes=cache_bytes, min_free_bytes=min_free_bytes
        )
        self.staging = self.root / "staging"
        self.private_roots = (self.root,)  # problem documents never show it

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
        return S3Incoming(self, f"uploads/{self._claim()}/{uuid.uuid4().hex}")

    def publish_upload(
        self, incoming: Incoming, *, project_id: str, dataset_id: str, filename: str, sha256: str
    ) -> str:
        """See :meth:`Blobs.publish_upload`: the upload's own key, completed in place.

        No copy: the object appears whole under the key it was received into. Until the
        :meth:`publishing` block ends, a marker (``pending/<instance>/<uuid>``, holding the
        dataset id) tells a sweep to delete the object if the dataset was never recorded.
        """
        del project_id, filename, sha256  # the row keeps them; deduplication asks the database
        if not isinstance(incoming, S3Incoming):
            msg = "only an upload to the bucket can be published in it"
            raise TypeError(msg)
        incoming.publish(dataset_id)
        self._publishing[dataset_id] = incoming
        return incoming.key

    @contextlib.contextmanager
    def publishing(self, dataset_id: str) -> Iterator[None]:
        """See :meth:`Blobs.publishing`: the pending marker goes once the block succeeded."""
        try:
            yield
        except BaseException:
            self._publishing.pop(dataset_id, None)  # the marker stays when the object might
            raise
        incoming = self._publishing.pop(dataset_id, None)
        if incoming is not None:
            incoming.done = True  # recorded (or removed): discarding the form keeps it
            with contextlib.suppress(BotoCoreError, ClientError):  # the sweep takes a leftover
                self.client.delete_object(
                    Bucket=self.bucket, Key=self.prefix + pending_key(incoming.key)
                )

    def remove_upload(self, dataset_id: str, storage_path: str) -> None:
        """See :meth:`Blobs.remove_upload` (and the upload's pending marker)."""
        del dataset_id
        with store_errors():
            self.client.delete_object(Bucket=self.bucket, Key=self.prefix + storage_path)
            if storage_path.startswith(UPLOAD_PREFIXES):
                for key in (held_key(storage_path), pending_key(storage_path)):
                    self.client.delete_object(Bucket=self.bucket, Key=self.prefix + key)

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

    def remote_file(self, storage_path: str, *, filename: str) -> ObjectFile | None:
        """See :meth:`Blobs.remote_file`: an ``.mcap`` or ``.bag`` file, read by ranges."""
        if PurePosixPath(filename).suffix.lower() not in {".mcap", ".bag"}:
            return None
        return ObjectFile(self.client, self.bucket, self.prefix + storage_path, name=filename)

    def job_input(
        self, storage_path: str, *, filename: str, sha256: str, size: int
    ) -> ObjectFile | None:
        """See :meth:`Blobs.job_input`: an MCAP file of ``ranged_bytes`` or more.

        Only an MCAP file whose index serves a few topics (a summary, chunk indexes,
        uncompressed chunks: three small reads tell) is read so. The tf and pose messages
        its upload held as it streamed through (``held/<instance>/<uuid>``) are read in one
        request; only other topics, or a file uploaded without them, go through the index.
        Compressed chunks and ROS 1 bags, whose chunks mix every topic, would be read whole
        one request after another, slower than the cache's parallel download.
        """
        from loceval.readers.rosbag import serves_by_index  # noqa: PLC0415  (rosbags: jobs only)

        if size < self.ranged_bytes or PurePosixPath(filename).suffix.lower() != ".mcap":
            return None
        if self.cache.holds(sha256, filename, size):
            return None
        key = self.prefix + storage_path
        held = (
            self.prefix + held_key(storage_path)
            if storage_path.startswith(UPLOAD_PREFIXES)
            else None
        )
        file = ObjectFile(self.client, self.bucket, key, name=filename, size=size, held_key=held)
        return file if serves_by_index(file) else None

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
        head = unless_missing(
            lambda: self.client.head_object(Bucket=self.bucket, Key=self.prefix + key)
        )
        return None if head is None else int(head["ContentLength"])

    def read_bytes(self, key: str) -> bytes:
        """See :meth:`Blobs.read_bytes`."""
        with store_errors():
            body = self.client.get_object(Bucket=self.bucket, Key=self.prefix + key)["Body"]
            return body.read()

    def download(self, key: str, *, media_type: str, filename: str, inline: bool) -> Download:
        """See :meth:`Blobs.download`: a presigned URL, or the object streamed through."""
        if self.redirect_s:
            disposition = content_disposition(filename, inline=inline)
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
            return Redirect(url)
        with store_errors():
            answer = self.client.get_object(Bucket=self.bucket, Key=self.prefix + key)
        return Stream(answer["Body"].iter_chunks(_DOWNLOAD_CHUNK), int(answer["ContentLength"]))

    # -- upkeep ----------------------------------------------------------------------------

    def sweep(
        self,
        recorded: Callable[[list[str]], Iterable[str]] = lambda _ids: (),
        *,
        older_than_s: float = STALE_UPLOAD_S,
        startup: bool = False,
    ) -> Swept:
        """See :meth:`Blobs.sweep`: what processes that are gone left (:mod:`.lease`).

        Aborts the open multipart uploads of instances that are gone, and deletes the
        uploads that were completed but never recorded (their pending markers) of
        instances that are gone or older than ``older_than_s``. A live process's uploads
        are kept whatever their age (a slow client's upload may take hours). At
        ``startup`` this process's identity is taken first: a gone process's slot in this
        data folder, whose leftovers are then all abandoned.
        """
        if startup:
            self._claim()
        leases, now = self._leases()

        def gone(instance: str) -> bool:
            if instance == self.instance:
                return startup
            renewed = leases.get(instance)
            return renewed is None or (now - renewed).total_seconds() > self.lease_s

        partial = 0
        with store_errors():
            paginator = self.client.get_paginator("list_multipart_uploads")
            for page in paginator.paginate(Bucket=self.bucket, Prefix=f"{self.prefix}uploads/"):
                for upload in page.get("Uploads", []):
                    if gone(_instance_of(upload["Key"], self.prefix + "uploads/")):
                        with contextlib.suppress(ClientError):  # finished meanwhile
                            self.client.abort_multipart_upload(
                                Bucket=self.bucket, Key=upload["Key"], UploadId=upload["UploadId"]
                            )
                        partial += 1
        markers = [
            item
            for item in self._list("pending/")
            if gone(_instance_of(item["Key"], self.prefix + "pending/"))
            or (now - item["LastModified"]).total_seconds() > older_than_s
        ]
        unrecorded = sum(self._settle(item["Key"], recorded) for item in markers)
        return Swept(partial_uploads=partial, datasets=unrecorded)

    def _settle(self, marker_key: str, recorded: Callable[[list[str]], Iterable[str]]) -> bool:
        """Delete a pending marker, and its upload when never recorded; return whether it was."""
        marker = marker_key[len(self.prefix) :]
        upload = "uploads/" + marker.removeprefix("pending/")
        dataset_id = self._marker(marker)
        if dataset_id is None:  # settled, or another sweep took it, meanwhile
            return False
        removed = dataset_id not in set(recorded([dataset_id]))
        with store_errors():
            if removed:
                for key in (upload, held_key(upload)):
                    self.client.delete_object(Bucket=self.bucket, Key=self.prefix + key)
            self.client.delete_object(Bucket=self.bucket, Key=marker_key)
        return removed

    def close(self) -> None:
        """See :meth:`Blobs.close`: the lease is deleted and the slot let go."""
        self.leave()

    def leave(self) -> None:
        """See :meth:`Blobs.leave`: the lease is deleted and the slot let go."""
        with self._instance_lock:
            if self._lease is not None:
                self._lease.stop()
                self._lease = None
            if self._slot is not None:
                self._slot.close()
                self._slot = None
            self.instance = None

    def cached_bytes(self) -> int:
        """See :meth:`Blobs.cached_bytes`."""
        return self.cache.size()

    def ping(self) -> None:
        """See :meth:`Blobs.ping`."""
        with store_errors():
            self.client.head_bucket(Bucket=self.bucket)

    # -- helpers ---------------------------------------------------------------------------

    def _claim(self) -> str:
        """Return this process's instance id, taking a slot and starting its lease first."""
        with self._instance_lock:
            if self.instance is None:
                instance, slot = claim_slot(self.root / "instances")
                key = f"{self.prefix}instances/{instance}"

                def renew() -> None:
                    self.client.put_object(Bucket=self.bucket, Key=key, Body=b"")

                def release() -> None:
                    self.client.delete_object(Bucket=self.bucket, Key=key)

                try:
                    with store_errors():
                        self._lease = Lease(renew, release, interval_s=self.lease_s / 4)
                except BaseException:
                    slot.close()
                    raise
                self.instance, self._slot = instance, slot
            return self.instance

    def _marker(self, key: str) -> str | None:
        """Return the dataset id a pending marker holds, or None when it is gone."""

        def read() -> bytes:  # the body's read fails like the request: both are guarded
            return self.client.get_object(Bucket=self.bucket, Key=self.prefix + key)["Body"].read()

        data = unless_missing(read)
        return None if data is None else data.decode(errors="replace")

    def _leases(self) -> tuple[dict[str, dt.datetime], dt.datetime]:
        """Return when each instance's lease was last renewed, and the store's time now."""
        leases: dict[str, dt.datetime] = {}
        now: dt.datetime | None = None
        with store_errors():
            paginator = self.client.get_paginator("list_objects_v2")
            for page in paginator.paginate(Bucket=self.bucket, Prefix=f"{self.prefix}instances/"):
                date = page.get("ResponseMetadata", {}).get("HTTPHeaders", {}).get("date")
                if date and now is None:
                    with contextlib.suppress(TypeError, ValueError):
                        now = email.utils.parsedate_to_datetime(date)
                for item in page.get("Contents", []):
                    instance = _instance_of(item["Key"], f"{self.prefix}instances/")
                    leases[instance] = item["LastModified"]
        return leases, now or dt.datetime.now(dt.UTC)

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


def _instance_of(key: str, folder: str) -> str:
    """Return the instance segment of ``<folder><instance>/<uuid>``."""
    return key.removeprefix(folder).split("/", 1)[0]
