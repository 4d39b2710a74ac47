"""``/api/v1/datasets``: upload, list, show and delete recordings."""

from __future__ import annotations

from typing import Annotated

import anyio.to_thread
from fastapi import APIRouter, Query, Request, Response, status

from service import datasets
from service.api.deps import ProjectDep, RuntimeDep
from service.api.responses import problems
from service.db import Dataset, get_owned
from service.metrics import count_upload
from service.schemas import DatasetPublic, DatasetsPublic
from service.uploads import receive_multipart

__all__ = ["router"]

router = APIRouter(prefix="/datasets", tags=["datasets"])

_UPLOAD_BODY = {
    "required": True,
    "content": {
        "multipart/form-data": {
            "schema": {
                "type": "object",
                "required": ["file"],
                "properties": {
                    "file": {"type": "string", "format": "binary"},
                    "name": {"type": "string", "maxLength": 300},
                    "tags": {"type": "string", "description": "comma-separated"},
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
    response_model=DatasetPublic,
    openapi_extra={"requestBody": _UPLOAD_BODY},
    responses={
        200: {"model": DatasetPublic, "description": "the same file was uploaded before"},
        **problems(400, 413, 507),
    },
)
async def create_dataset(
    request: Request, response: Response, runtime: RuntimeDep, project_id: ProjectDep
) -> DatasetPublic:
    """Upload a recording (multipart field ``file``), streamed to disk and inspected.

    Re-uploading identical bytes returns the existing dataset with 200.
    """
    form = await receive_multipart(
        request,
        runtime.store,
        max_bytes=runtime.settings.max_upload_bytes,
        file_fields=frozenset({"file"}),
        min_free_bytes=runtime.settings.min_free_bytes,
    )
    try:
        dataset, created = await anyio.to_thread.run_sync(
            lambda: datasets.store_form(runtime, project_id, form)
        )
    finally:
        form.discard()
    count_upload(request, form)
    if not created:
        response.status_code = status.HTTP_200_OK
    response.headers["Location"] = f"{request.base_url}api/v1/datasets/{dataset.id}"
    return dataset_public(dataset)


@router.get("", response_model=DatasetsPublic, responses=problems())
def read_datasets(
    runtime: RuntimeDep,
    project_id: ProjectDep,
    tag: Annotated[str | None, Query(max_length=50)] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 100,
    offset: Annotated[int, Query(ge=0, le=1_000_000)] = 0,
) -> DatasetsPublic:
    """List the project's datasets, newest first (optionally those with a tag)."""
    rows, count = datasets.list_datasets(runtime, project_id, tag=tag, limit=limit, offset=offset)
    return DatasetsPublic(items=[dataset_public(d) for d in rows], count=count)


@router.get("/{dataset_id}", response_model=DatasetPublic, responses=problems(404))
def read_dataset(dataset_id: str, runtime: RuntimeDep, project_id: ProjectDep) -> DatasetPublic:
    """Show one dataset with its inspection."""
    return dataset_public(get_owned(runtime.sessions, Dataset, dataset_id, project_id))


@router.delete(
    "/{dataset_id}", status_code=status.HTTP_204_NO_CONTENT, responses=problems(404, 409)
)
def delete_dataset(dataset_id: str, runtime: RuntimeDep, project_id: ProjectDep) -> Response:
    """Delete a dataset and its file (refused while a queued or running evaluation uses it).

    Finished evaluations keep their results and artifacts.
    """
    datasets.delete_dataset(runtime, project_id, dataset_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
