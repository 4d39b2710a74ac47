"""Where uploads and artifacts live: the data folder, or an S3-compatible bucket.

:func:`open_blobs` picks the backend from the settings: ``LOCEVAL_BLOB_URL`` empty (the
default) keeps everything in ``LOCEVAL_DATA_DIR``; ``s3://bucket/prefix`` puts uploads,
artifacts and schedule summaries in the bucket (see :mod:`service.blobs.s3`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from service.blobs.base import HEAD_BYTES, Blobs, Incoming, artifact_key
from service.blobs.local import LocalBlobs

if TYPE_CHECKING:
    from service.settings import Settings

__all__ = ["HEAD_BYTES", "Blobs", "Incoming", "LocalBlobs", "artifact_key", "open_blobs"]


def open_blobs(settings: Settings) -> Blobs:
    """Return the blob store the settings name.

    Raises:
        StartupError: the bucket cannot be reached (the message says what to check), or
            boto3 is not installed.
    """
    if not settings.blob_url:
        return LocalBlobs(settings.data_dir)
    try:
        from service.blobs.s3 import S3Blobs  # noqa: PLC0415  (boto3: the "scale" extra)
    except ImportError as err:  # pragma: no cover  (installed with the scale extra)
        from service.errors import StartupError  # noqa: PLC0415

        msg = (
            f"LOCEVAL_BLOB_URL names a bucket but boto3 is not installed ({err}); install "
            "loceval[scale]."
        )
        raise StartupError(msg) from None
    store = S3Blobs(
        settings.blob_url,
        settings.data_dir,
        cache_bytes=settings.blob_cache_bytes,
        min_free_bytes=settings.min_free_bytes,
        redirect_s=settings.blob_redirect_s,
        ranged_bytes=settings.blob_ranged_bytes,
    )
    store.check_bucket()
    return store
