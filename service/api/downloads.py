"""The response of a download: made here from what the blob store hands out.

A store says what to send (:data:`service.blobs.base.Download`): a file on this machine, a
presigned URL the client fetches from the bucket itself, or the object's bytes passed
through. The HTTP response is the routes' business, and made only here.
"""

from __future__ import annotations

from starlette.responses import FileResponse, RedirectResponse, Response, StreamingResponse

from service.blobs.base import Blobs, LocalFile, Redirect, Stream, content_disposition

__all__ = ["download_response"]


def download_response(
    store: Blobs, key: str, *, media_type: str, filename: str, inline: bool
) -> Response:
    """Return the response that downloads a blob: the file, a 307 redirect, or a stream.

    Args:
        store: the blob store.
        key: the blob.
        media_type: its media type.
        filename: the name the client saves it under (``download_filename``).
        inline: shown in the browser rather than saved.
    """
    found = store.download(key, media_type=media_type, filename=filename, inline=inline)
    disposition = {"content-disposition": content_disposition(filename, inline=inline)}
    if isinstance(found, LocalFile):
        return FileResponse(found.path, media_type=media_type, headers=disposition)
    if isinstance(found, Redirect):
        return RedirectResponse(found.url, status_code=307)
    assert isinstance(found, Stream)  # noqa: S101  (the three kinds of Download)
    headers = {"content-length": str(found.size), **disposition}
    return StreamingResponse(found.chunks, media_type=media_type, headers=headers)
