"""``/api/v1/datasets``: upload, list, show and delete recordings."""

from __future__ import annotations

from typing import Annotated, Final

import anyio.to_thread
from fastapi import APIRouter, Query, Request, Response, status

from loceval.errors import ReaderError
from service.api.deps import PathText, ProjectDep, RuntimeDep
from service.api.links import api_url
from service.api.metrics import count_upload
from service.api.multipart import receive_multipart
from service.api.responses import not_found, problem_example, problems
from service.blobs.base import MAX_FILENAME_BYTES
from service.db import Dataset, get_owned
from service.errors import ConflictError
from service.schemas.base import NO_NUL
from service.schemas.evaluations import (
    MAX_DATASET_NAME,
    MAX_TAG,
    MAX_TAGS,
    DatasetPublic,
    DatasetsPublic,
    DatasetUploaded,
)
from service.uploads import datasets

__all__ = ["router"]

router = APIRouter(prefix="/datasets", tags=["datasets"])

_EXAMPLES: Final = {
    404: not_found("datasets", "26dcd1ee-d6ab-43f3-a9d1-7de7c3c461b6"),
    409: problem_example(
        ConflictError,
        409,
        "Dataset 'fr2_desk_ORB.txt' is used by an evaluation that has not finished; delete it "
        "when the evaluation is done.",
    ),
}
_PRINTABLE = r"^[^\x00-\x1f\x7f]*$"  # control characters are refused (422)
_UPLOAD_BODY = {
    "required": True,
    "content": {
        "multipart/form-data": {
            "schema": {
                "type": "object",
                "required": ["file"],
                "additionalProperties": False,
                "properties": {
                    "file": {
                        "type": "string",
                        "format": "binary",
                        "description": "the recording; its file name is stored sanitised "
                        f"(no folders, at most {MAX_FILENAME_BYTES} bytes)",
                    },
                    "name": {
                        "type": "string",
                        "maxLength": MAX_DATASET_NAME,
                        "pattern": _PRINTABLE,
                        "description": "default (or empty): the file name; a longer name or "
                        "one with control characters is refused (422), never shortened",
                    },
                    "tags": {
                        "type": "string",
                        "pattern": _PRINTABLE,
                        "description": f"comma-separated, at most {MAX_TAGS} tags of up to "
                        f"{MAX_TAG} characters; longer ones are refused (422)",
                    },
                },
            }
        }
    },
}


def dataset_public(dataset: Dataset) -> DatasetPublic:
    """Return the HTTP view of a dataset."""
    return DatasetPublic.model_validate(dataset, from_attributes=True)


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    response_model=DatasetUploaded,
    openapi_extra={"requestBody": _UPLOAD_BODY},
    responses={
        200: {
            "model": DatasetUploaded,
            "description": "the same bytes were uploaded before: that dataset, with this "
            "request's tags merged in (see upload)",
        },
        **problems(
            400,
            413,
            507,
            examples={
                422: problem_example(
                    ReaderError,
                    422,
                    "Cannot tell the format of 'run-03.bin' from its first lines; name it with "
                    "a prefix, e.g. tum:run-03.bin (one of tum, euroc, kitti, csv, motive, bag, "
                    "points).",
                )
            },
        ),
    },
)
async def create_dataset(
    request: Request, response: Response, runtime: RuntimeDep, project_id: ProjectDep
) -> DatasetUploaded:
    """Upload a recording (multipart field ``file``), streamed to disk and inspected.

    Identical bytes are stored once per project: uploading them again answers 200 with
    the existing dataset, this request's tags merged into its tags and its name kept.
    ``upload`` reports what became of the request (tags added, name kept, file name
    sanitised). A name or tag over its limit is refused with 422, never shortened.
    """
    form = await receive_multipart(
        request,
        runtime.store,
        max_bytes=runtime.settings.max_upload_bytes,
        file_fields=frozenset({"file"}),
        min_free_bytes=runtime.settings.min_free_bytes,
        text_fields=frozenset({"name", "tags"}),
    )
    try:
        dataset, report = await anyio.to_thread.run_sync(
            lambda: datasets.store_form(runtime, project_id, form)
        )
    finally:
        form.discard()
    count_upload(request, form)
    if report.deduplicated:
        response.status_code = status.HTTP_200_OK
    response.headers["Location"] = api_url(runtime.settings, "datasets", dataset.id)
    return DatasetUploaded.model_validate(
        {**dataset_public(dataset).model_dump(), "upload": report}
    )


@router.get("", response_model=DatasetsPublic, responses=problems())
def read_datasets(
    runtime: RuntimeDep,
    project_id: ProjectDep,
    *,
    tag: Annotated[str | None, Query(max_length=50, pattern=NO_NUL)] = None,
    sha256: Annotated[
        str | None,
        Query(
            pattern=r"^[0-9a-fA-F]{64}$",
            description="the file's SHA-256 (hex): the dataset holding these bytes, if any",
        ),
    ] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 100,
    offset: Annotated[int, Query(ge=0, le=1_000_000)] = 0,
) -> DatasetsPublic:
    """List the project's datasets, newest first (optionally those with a tag or checksum).

    ``?sha256=`` asks whether the project holds a file already (``loceval submit`` uploads
    only the files it does not): one item, or none.
    """
    rows, count = datasets.list_datasets(
        runtime, project_id, tag=tag, sha256=sha256, limit=limit, offset=offset
    )
    return DatasetsPublic(items=[dataset_public(d) for d in rows], count=count)


@router.get(
    "/{dataset_id}", response_model=DatasetPublic, responses=problems(404, examples=_EXAMPLES)
)
def read_dataset(
    dataset_id: PathText, runtime: RuntimeDep, project_id: ProjectDep
) -> DatasetPublic:
    """Show one dataset with its inspection."""
    return dataset_public(get_owned(runtime.sessions, Dataset, dataset_id, project_id))


@router.delete(
    "/{dataset_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    responses=problems(404, 409, 507, examples=_EXAMPLES),
)
def delete_dataset(dataset_id: PathText, runtime: RuntimeDep, project_id: ProjectDep) -> Response:
    """Delete a dataset and its file (refused while a queued or running evaluation uses it).

    Finished evaluations keep their results and artifacts.
    """
    datasets.delete_dataset(runtime, project_id, dataset_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
