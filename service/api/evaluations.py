"""``/api/v1/evaluations`` and the one-shot ``/api/v1/evaluate``."""

from __future__ import annotations

import json
from typing import Annotated, Literal

import anyio.to_thread
from fastapi import APIRouter, Query, Request, Response, status
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse
from pydantic import ValidationError
from sqlalchemy import select

from exporters import ARTIFACTS
from service.api.deps import ProjectDep, RuntimeDep
from service.api.responses import problems
from service.datasets import store_upload
from service.db import Evaluation, EvaluationStatus, get_owned
from service.errors import NotFoundError, NotReadyError, UploadError
from service.evaluations import create_evaluation, evaluation_public
from service.jobs import Runtime
from service.schemas import (
    EvaluationCreate,
    EvaluationOptions,
    EvaluationPublic,
    EvaluationsPublic,
)
from service.uploads import ReceivedForm, receive_multipart

__all__ = ["router"]

router = APIRouter(tags=["evaluations"])

_INLINE = frozenset({"report.html", "report.pdf"})
_MAX_ESTIMATES = 20


@router.post(
    "/evaluations",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=EvaluationPublic,
    responses=problems(404, 503),
)
def create_evaluation_job(
    body: EvaluationCreate,
    request: Request,
    response: Response,
    runtime: RuntimeDep,
    project_id: ProjectDep,
) -> EvaluationPublic:
    """Queue an evaluation of uploaded datasets; poll ``GET /evaluations/{id}`` for it."""
    evaluation = create_evaluation(runtime, project_id, body)
    response.headers["Location"] = f"{request.base_url}api/v1/evaluations/{evaluation.id}"
    return evaluation_public(evaluation, base_url=str(request.base_url), with_result=False)


@router.get("/evaluations", response_model=EvaluationsPublic, responses=problems())
def read_evaluations(  # noqa: PLR0917  (FastAPI passes dependencies and queries by name)
    request: Request,
    runtime: RuntimeDep,
    project_id: ProjectDep,
    status_: Annotated[
        Literal["queued", "running", "succeeded", "failed"] | None, Query(alias="status")
    ] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 100,
    offset: Annotated[int, Query(ge=0, le=1_000_000)] = 0,
) -> EvaluationsPublic:
    """List the project's evaluations, newest first, without their result documents."""
    with runtime.sessions() as session:
        query = select(Evaluation).where(Evaluation.project_id == project_id)
        if status_ is not None:
            query = query.where(Evaluation.status == status_)
        rows = session.scalars(query.order_by(Evaluation.created_at.desc(), Evaluation.id)).all()
    base = str(request.base_url)
    items = [evaluation_public(e, base_url=base, with_result=False) for e in rows]
    return EvaluationsPublic(items=items[offset : offset + limit], count=len(items))


@router.get(
    "/evaluations/{evaluation_id}", response_model=EvaluationPublic, responses=problems(404)
)
def read_evaluation(
    evaluation_id: str, request: Request, runtime: RuntimeDep, project_id: ProjectDep
) -> EvaluationPublic:
    """Status and progress; the result document once succeeded, the problem once failed."""
    evaluation = get_owned(runtime.sessions, Evaluation, evaluation_id, project_id)
    return evaluation_public(evaluation, base_url=str(request.base_url), with_result=True)


@router.get(
    "/evaluations/{evaluation_id}/artifacts/{name}",
    response_class=FileResponse,
    responses={
        200: {
            "description": "the file",
            "content": {spec.media_type: {} for spec in ARTIFACTS.values()},
        },
        **problems(404, 409),
    },
)
def read_artifact(
    evaluation_id: str, name: str, runtime: RuntimeDep, project_id: ProjectDep
) -> FileResponse:
    """Download an artifact: report.html, report.pdf, errors.csv, result.json, paths.*."""
    evaluation = get_owned(runtime.sessions, Evaluation, evaluation_id, project_id)
    spec = ARTIFACTS.get(name)
    if spec is None:
        msg = f"No artifact {name!r}; the artifacts are {', '.join(ARTIFACTS)}."
        raise NotFoundError(msg)
    if evaluation.status != EvaluationStatus.SUCCEEDED:
        msg = f"Evaluation {evaluation_id!r} is {evaluation.status}, so it has no artifacts" + (
            " yet; poll GET /evaluations/{id} until it succeeds."
            if evaluation.status in EvaluationStatus.ACTIVE
            else "; see its error."
        )
        raise NotReadyError(msg)
    path = runtime.store.artifacts_dir(evaluation.id) / name
    if not path.is_file():
        msg = f"Evaluation {evaluation_id!r} did not write {name!r} (its formats left it out)."
        raise NotFoundError(msg)
    return FileResponse(
        path,
        media_type=spec.media_type,
        filename=f"loceval-{evaluation.id[:8]}-{name}",
        content_disposition_type="inline" if name in _INLINE else "attachment",
    )


_ONE_SHOT_BODY = {
    "required": True,
    "content": {
        "multipart/form-data": {
            "schema": {
                "type": "object",
                "required": ["reference"],
                "properties": {
                    "reference": {"type": "string", "format": "binary"},
                    "estimate": {
                        "type": "array",
                        "items": {"type": "string", "format": "binary"},
                        "description": "omit when the reference file holds the estimates too",
                    },
                    "reference_selector": {"type": "string"},
                    "estimate_selector": {"type": "array", "items": {"type": "string"}},
                    "estimate_name": {"type": "array", "items": {"type": "string"}},
                    "options": {"type": "string", "description": "JSON of the options object"},
                },
            }
        }
    },
}


@router.post(
    "/evaluate",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=EvaluationPublic,
    openapi_extra={"requestBody": _ONE_SHOT_BODY},
    responses=problems(400, 404, 413, 503),
)
async def evaluate_upload(
    request: Request, response: Response, runtime: RuntimeDep, project_id: ProjectDep
) -> EvaluationPublic:
    """Upload files and start their evaluation in one request (for scripts on site laptops).

    Each file becomes a dataset (as with ``POST /datasets``); without ``estimate`` files
    the estimates are read from the reference file (one bag holding both), chosen by
    ``estimate_selector``.
    """
    form = await receive_multipart(
        request,
        runtime.store,
        max_bytes=runtime.settings.max_upload_bytes,
        file_fields=frozenset({"reference", "estimate"}),
        max_files=1 + _MAX_ESTIMATES,
    )
    try:
        evaluation = await anyio.to_thread.run_sync(
            lambda: _evaluate_form(runtime, project_id, form)
        )
    finally:
        form.discard()
    response.headers["Location"] = f"{request.base_url}api/v1/evaluations/{evaluation.id}"
    return evaluation_public(evaluation, base_url=str(request.base_url), with_result=False)


def _evaluate_form(runtime: Runtime, project_id: str, form: ReceivedForm) -> Evaluation:
    references = [f for f in form.files if f.field == "reference"]
    estimates = [f for f in form.files if f.field == "estimate"]
    if len(references) != 1:
        msg = f"Send exactly one file in the field 'reference', got {len(references)}."
        raise UploadError(msg)
    options = _options(form.value("options"))
    selectors = form.values("estimate_selector")
    names = form.values("estimate_name")
    count = len(estimates) or len(selectors)
    if count == 0:
        msg = (
            "Name the estimates: send 'estimate' files, or 'estimate_selector' values when "
            "the reference file holds them (a bag)."
        )
        raise UploadError(msg)
    if estimates and selectors and len(selectors) != len(estimates):
        msg = f"Send one estimate_selector per estimate file ({len(estimates)}), or none."
        raise UploadError(msg)
    if names and len(names) != count:
        msg = f"Send one estimate_name per estimate ({count}), or none."
        raise UploadError(msg)
    reference_ref: dict[str, str | None] = {
        "dataset_id": "pending",
        "selector": form.value("reference_selector"),
    }
    estimate_refs: list[dict[str, str | None]] = [
        {
            "dataset_id": "pending",
            "selector": (selectors[k] or None) if selectors else None,
            "name": (names[k] or None) if names else None,
        }
        for k in range(count)
    ]
    draft = {"reference": reference_ref, "estimates": estimate_refs, "options": options}
    try:  # checked before any file is stored; every error names its place (estimates.0.name)
        EvaluationCreate.model_validate(draft)
    except ValidationError as err:
        raise RequestValidationError(err.errors()) from None
    reference, _ = store_upload(runtime, project_id, references[0])
    stored = [store_upload(runtime, project_id, f)[0] for f in estimates]
    reference_ref["dataset_id"] = reference.id
    for k, estimate in enumerate(estimate_refs):
        estimate["dataset_id"] = stored[k].id if stored else reference.id
    body = EvaluationCreate.model_validate(draft)
    return create_evaluation(runtime, project_id, body)


def _options(text: str | None) -> EvaluationOptions:
    if not text:
        return EvaluationOptions()
    try:
        json.loads(text)
    except json.JSONDecodeError as err:
        msg = f"The 'options' field is not JSON ({err.msg} at character {err.pos})."
        raise UploadError(msg) from None
    try:
        return EvaluationOptions.model_validate_json(text)
    except ValidationError as err:
        errors = [{**e, "loc": ("options", *e["loc"])} for e in err.errors()]
        raise RequestValidationError(errors) from None
