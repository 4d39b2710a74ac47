"""``/api/v1/uploads``: resumable uploads with the tus 1.0 protocol (the HTTP side).

The protocol is :mod:`service.uploads.tus`; here its headers are read and written. Every
answer under ``/api/v1/uploads`` carries ``Tus-Resumable`` (errors and 401s too:
:class:`TusHeadersMiddleware`) and exposes the tus headers to a page's scripts.
"""

from __future__ import annotations

import email.utils
from collections.abc import AsyncIterator
from typing import Any, Final

import anyio.to_thread
from fastapi import APIRouter, Depends, Request, Response, status
from starlette.requests import ClientDisconnect
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.api.datasets import dataset_public
from service.api.deps import PathText, ProjectDep, RuntimeDep
from service.api.links import api_url
from service.api.responses import problems
from service.db import Dataset, TusUpload
from service.errors import UploadError
from service.runtime import Runtime
from service.schemas.evaluations import UploadPublic
from service.schemas.uploads import ResumableUploadPublic
from service.uploads import tus
from service.uploads.multipart import INTERRUPTED

__all__ = ["DATASET_HEADER", "TusHeadersMiddleware", "router"]

DATASET_HEADER: Final = "Loceval-Dataset"
"""The header of the answer that completes an upload: the dataset it became."""
_PATH: Final = "/api/v1/uploads"
_EXPOSED: Final = (
    "Tus-Resumable, Tus-Version, Tus-Extension, Tus-Max-Size, Tus-Checksum-Algorithm, "
    f"Upload-Offset, Upload-Length, Upload-Metadata, Upload-Expires, Location, {DATASET_HEADER}"
)


def _version(request: Request) -> None:
    """Refuse a request that does not speak tus 1.0.0 (412)."""
    tus.check_version(request.headers.get("tus-resumable"))


router = APIRouter(prefix="/uploads", tags=["uploads"])
_TUS = [Depends(_version)]
_DIGITS = {"type": "string", "pattern": "^[0-9]{1,19}$"}


def _header(
    name: str, schema: dict[str, Any], description: str, *, required: bool = True
) -> dict[str, Any]:
    return {
        "name": name,
        "in": "header",
        "required": required,
        "schema": schema,
        "description": description,
    }


_VERSION = _header(
    "Tus-Resumable", {"type": "string", "enum": [tus.TUS_VERSION]}, "the protocol's version"
)
_CHECKSUM = _header(
    "Upload-Checksum",
    {"type": "string"},
    "'sha1 BASE64', 'sha256 BASE64' or 'md5 BASE64': the digest of this body",
    required=False,
)
_OCTETS = {
    "required": False,
    "content": {tus.OFFSET_MEDIA_TYPE: {"schema": {"type": "string", "format": "binary"}}},
}


def _http_date(row: TusUpload) -> str:
    return email.utils.format_datetime(row.expires_at, usegmt=True)


def _progress(row: TusUpload, dataset_id: str | None = None) -> dict[str, str]:
    headers = {"Upload-Offset": str(row.offset), "Upload-Expires": _http_date(row)}
    if dataset_id is not None:
        headers[DATASET_HEADER] = dataset_id
    return headers


async def _body(request: Request) -> AsyncIterator[bytes]:
    """The request's bytes; a client that went away is an interrupted upload."""
    try:
        async for chunk in request.stream():
            yield chunk
    except ClientDisconnect:
        raise UploadError(INTERRUPTED) from None


@router.options(
    "", status_code=status.HTTP_204_NO_CONTENT, response_class=Response, responses=problems()
)
def upload_options(runtime: RuntimeDep, project_id: ProjectDep) -> Response:
    """The server's tus capabilities: version, extensions, largest upload, checksums."""
    del project_id
    return Response(
        status_code=status.HTTP_204_NO_CONTENT,
        headers={
            "Tus-Version": tus.TUS_VERSION,
            "Tus-Extension": ",".join(tus.EXTENSIONS),
            "Tus-Max-Size": str(runtime.settings.max_upload_bytes),
            "Tus-Checksum-Algorithm": ",".join(tus.CHECKSUM_ALGORITHMS),
        },
    )


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    response_class=Response,
    dependencies=_TUS,
    responses=problems(400, 412, 413, 415, 460, 507),
    openapi_extra={
        "parameters": [
            _VERSION,
            _header("Upload-Length", _DIGITS, "the file's size in bytes"),
            _header(
                "Upload-Metadata",
                {"type": "string"},
                "'filename B64,name B64,tags B64': each value base64 of UTF-8 text",
                required=False,
            ),
            _CHECKSUM,
        ],
        "requestBody": _OCTETS,
    },
)
async def create_upload(request: Request, runtime: RuntimeDep, project_id: ProjectDep) -> Response:
    """Create a resumable upload (tus creation; with a body, creation-with-upload).

    ``Upload-Length`` is the file's size; ``Upload-Metadata`` may carry ``filename``, the
    dataset's ``name`` and its ``tags`` (comma-separated), each base64-encoded. The answer's
    ``Location`` is the upload's address; a body sent along is written at once.
    """
    row = await anyio.to_thread.run_sync(
        lambda: tus.create_upload(
            runtime,
            project_id,
            length=request.headers.get("upload-length"),
            metadata=request.headers.get("upload-metadata"),
        )
    )
    headers = {"Location": api_url(runtime.settings, "uploads", row.id), **_progress(row)}
    content_type = request.headers.get("content-type")
    sent = request.headers.get("content-length", "0") != "0" or (
        "transfer-encoding" in request.headers
    )
    if sent or row.length == 0 or content_type == tus.OFFSET_MEDIA_TYPE:
        received = await tus.receive(
            runtime,
            project_id,
            row.id,
            _body(request),
            offset="0",
            content_type=content_type if sent else tus.OFFSET_MEDIA_TYPE,
            content_length=request.headers.get("content-length"),
            checksum=request.headers.get("upload-checksum"),
        )
        headers.update(_progress(received.upload, received.dataset_id))
    return Response(status_code=status.HTTP_201_CREATED, headers=headers)


@router.head(
    "/{upload_id}",
    response_class=Response,
    dependencies=_TUS,
    responses=problems(404, 412),
    openapi_extra={"parameters": [_VERSION]},
)
def upload_offset(upload_id: PathText, runtime: RuntimeDep, project_id: ProjectDep) -> Response:
    """How many bytes of the upload the server holds (``Upload-Offset``)."""
    row = tus.settle(runtime, project_id, upload_id)
    headers = {
        "Upload-Offset": str(row.offset),
        "Upload-Length": str(row.length),
        "Cache-Control": "no-store",
        "Upload-Expires": _http_date(row),
    }
    if row.metadata_header:
        headers["Upload-Metadata"] = row.metadata_header
    if row.dataset_id is not None:
        headers[DATASET_HEADER] = row.dataset_id
    return Response(status_code=status.HTTP_200_OK, headers=headers)


@router.patch(
    "/{upload_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    response_class=Response,
    dependencies=_TUS,
    responses=problems(400, 404, 409, 412, 413, 415, 423, 460, 507),
    openapi_extra={
        "parameters": [
            _VERSION,
            _header("Upload-Offset", _DIGITS, "where the bytes go: the upload's offset"),
            _CHECKSUM,
        ],
        "requestBody": {**_OCTETS, "required": True},
    },
)
async def upload_bytes(
    upload_id: PathText, request: Request, runtime: RuntimeDep, project_id: ProjectDep
) -> Response:
    """Append bytes at ``Upload-Offset`` (``Content-Type: application/offset+octet-stream``).

    An optional ``Upload-Checksum`` (``sha1``, ``sha256`` or ``md5``, base64) must match the
    body (else 460 and nothing is kept). The answer that completes the upload names the
    dataset it became in ``Loceval-Dataset``.
    """
    received = await tus.receive(
        runtime,
        project_id,
        upload_id,
        _body(request),
        offset=request.headers.get("upload-offset"),
        content_type=request.headers.get("content-type"),
        content_length=request.headers.get("content-length"),
        checksum=request.headers.get("upload-checksum"),
    )
    return Response(
        status_code=status.HTTP_204_NO_CONTENT,
        headers=_progress(received.upload, received.dataset_id),
    )


@router.delete(
    "/{upload_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    response_class=Response,
    dependencies=_TUS,
    responses=problems(404, 412, 423, 507),
    openapi_extra={"parameters": [_VERSION]},
)
def delete_upload(upload_id: PathText, runtime: RuntimeDep, project_id: ProjectDep) -> Response:
    """Terminate an upload: its bytes go (a finished upload's dataset stays)."""
    tus.delete_upload(runtime, project_id, upload_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.get("/{upload_id}", response_model=ResumableUploadPublic, responses=problems(404))
def read_upload(
    upload_id: PathText, runtime: RuntimeDep, project_id: ProjectDep
) -> ResumableUploadPublic:
    """An upload's progress and, once complete, the dataset it became."""
    row = tus.settle(runtime, project_id, upload_id, wait=False)
    return upload_public(runtime, row)


def upload_public(runtime: Runtime, row: TusUpload) -> ResumableUploadPublic:
    """Return the HTTP view of an upload."""
    dataset = None
    if row.dataset_id is not None:
        with runtime.sessions() as session:
            found = session.get(Dataset, row.dataset_id)
        dataset = None if found is None else dataset_public(found)
    return ResumableUploadPublic(
        id=row.id,
        offset=row.offset,
        length=row.length,
        filename=row.filename,
        name=row.name,
        tags=list(row.tags),
        expires=row.expires_at,
        dataset=dataset,
        upload=None if row.report is None else UploadPublic.model_validate(row.report),
        error=row.error,
    )


class TusHeadersMiddleware:
    """Add ``Tus-Resumable`` (and the exposed headers) to every answer under the uploads."""

    def __init__(self, app: ASGIApp) -> None:
        """Wrap the application."""
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Pass the request on; add the headers to its answer."""
        path = str(scope.get("path", ""))
        if scope["type"] != "http" or not (path == _PATH or path.startswith(_PATH + "/")):
            await self.app(scope, receive, send)
            return

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                names = {name.lower() for name, _ in headers}
                extra = [
                    (b"tus-resumable", tus.TUS_VERSION.encode()),
                    (b"access-control-expose-headers", _EXPOSED.encode()),
                ]
                if message["status"] == 412:
                    extra.append((b"tus-version", tus.TUS_VERSION.encode()))
                headers += [(k, v) for k, v in extra if k not in names]
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_with_headers)
