"""The HTTP contract of resumable uploads (``/api/v1/uploads``, tus 1.0): an upload's state."""

from __future__ import annotations

import datetime as dt
from typing import Any

from pydantic import BaseModel, Field

from service.schemas.evaluations import DatasetPublic, UploadPublic

__all__ = ["ResumableUploadPublic"]


class ResumableUploadPublic(BaseModel):
    """A resumable upload: how far it is, and the dataset it became once complete."""

    id: str
    offset: int = Field(description="bytes received (what HEAD answers as Upload-Offset)")
    length: int = Field(description="the upload's size in bytes (Upload-Length)")
    filename: str = Field(description="the file name sent in Upload-Metadata")
    name: str | None = Field(description="the dataset's name sent in Upload-Metadata")
    tags: list[str]
    expires: dt.datetime = Field(
        description="when an unfinished upload is removed (Upload-Expires); each write moves it on"
    )
    dataset: DatasetPublic | None = Field(
        description="the dataset it became (as GET /datasets/{id} shows it), or null while "
        "unfinished"
    )
    upload: UploadPublic | None = Field(
        default=None,
        description="what became of the file name, name and tags (as POST /datasets says)",
    )
    error: dict[str, Any] | None = Field(
        default=None,
        description="the problem document of a complete upload that could not become a dataset",
    )
