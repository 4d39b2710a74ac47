"""``/api/v1/datasets``: upload, list, show and delete recordings."""

from __future__ import annotations

from typing import Annotated

import anyio.to_thread
from fastapi import APIRouter, Query, Request, Response, status
from sqlalchemy import select

from service.api.deps import ProjectDep, RuntimeDep
from service.api.responses import problems
from service.datasets import parse_tags, store_upload
from service.db import Dataset, Evaluation, EvaluationStatus, get_owned
from service.errors import ConflictError, UploadError
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
        **problems(400, 413),
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
    )
    try:
        if not form.files:
            msg = "The upload has no file; send it in the multipart field 'file'."
            raise UploadError(msg)
        tags = parse_tags(",".join(form.values("tags")))
        dataset, created = await anyio.to_thread.run_sync(
            lambda: store_upload(
                runtime, project_id, form.files[0], name=form.value("name"), tags=tags
            )
        )
    finally:
        form.discard()
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
    with runtime.sessions() as session:
        query = select(Dataset).where(Dataset.project_id == project_id)
        rows = session.scalars(query.order_by(Dataset.created_at.desc(), Dataset.id)).all()
    if tag is not None:
        rows = [d for d in rows if tag in d.tags]
    page = rows[offset : offset + limit]
    return DatasetsPublic(items=[dataset_public(d) for d in page], count=len(rows))


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
    dataset = get_owned(runtime.sessions, Dataset, dataset_id, project_id)
    with runtime.sessions() as session:
        active = session.scalars(
            select(Evaluation.dataset_ids).where(
                Evaluation.project_id == project_id,
                Evaluation.status.in_(EvaluationStatus.ACTIVE),
            )
        ).all()
        if any(dataset.id in ids for ids in active):
            msg = (
                f"Dataset {dataset.name!r} is used by an evaluation that has not finished; "
                "delete it when the evaluation is done."
            )
            raise ConflictError(msg)
        session.delete(session.get_one(Dataset, dataset.id))
        session.commit()
    runtime.store.remove_dataset(dataset.id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
