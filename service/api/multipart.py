"""A multipart request received into the blob store: the HTTP side of :mod:`service.uploads`.

:func:`service.uploads.multipart.receive_multipart` reads any body with headers and a
stream of bytes, and knows no web framework; here the request is Starlette's, whose stream
raises :class:`~starlette.requests.ClientDisconnect` when the client goes away mid-body.
The receiver has deleted what it received by then; the client is told it was interrupted.
"""

from __future__ import annotations

from starlette.requests import ClientDisconnect, Request

from service.blobs.base import Blobs
from service.errors import UploadError
from service.uploads.multipart import INTERRUPTED, ReceivedForm
from service.uploads.multipart import receive_multipart as _receive

__all__ = ["receive_multipart"]


async def receive_multipart(
    request: Request,
    store: Blobs,
    *,
    max_bytes: int,
    file_fields: frozenset[str],
    text_fields: frozenset[str] | None = None,
    max_files: int = 1,
    min_free_bytes: int = 0,
) -> ReceivedForm:
    """Stream a ``multipart/form-data`` request into the blob store.

    See :func:`service.uploads.multipart.receive_multipart` for the arguments and what is
    refused.

    Raises:
        UploadError: also when the client went away before the body was complete.
    """
    try:
        return await _receive(
            request,
            store,
            max_bytes=max_bytes,
            file_fields=file_fields,
            text_fields=text_fields,
            max_files=max_files,
            min_free_bytes=min_free_bytes,
        )
    except ClientDisconnect:
        raise UploadError(INTERRUPTED) from None
