"""``/api/v1/evaluations``, the one-shot ``/api/v1/evaluate`` and ``/api/v1/ranging``."""

from __future__ import annotations

from typing import Annotated, Final, Literal

import anyio.to_thread
from fastapi import APIRouter, Query, Request, Response, status
from fastapi.responses import FileResponse

from exporters import ARTIFACTS
from service.api.deps import PathText, ProjectDep, RuntimeDep
from service.api.downloads import download_response
from service.api.links import api_url, public_base
from service.api.metrics import count_upload
from service.api.multipart import receive_multipart
from service.api.responses import UNREADABLE, problem_example, problems
from service.db import Evaluation, get_owned
from service.errors import NotReadyError, UploadError
from service.jobs import evaluations, retention
from service.runtime import Runtime
from service.schemas.base import NO_NUL
from service.schemas.evaluations import (
    EvaluationCreate,
    EvaluationPublic,
    EvaluationsPublic,
    OptionsPublic,
    RangingCreate,
    options_public,
)

__all__ = ["router"]

router = APIRouter(tags=["evaluations"])

_INLINE = frozenset({"report.html", "report.pdf"})
_MAX_ESTIMATES = 20
_ONE_SHOT_FIELDS = frozenset(
    {"reference_selector", "estimate_selector", "estimate_name", "options"}
)


def _accepted(evaluation: Evaluation, response: Response, runtime: Runtime) -> EvaluationPublic:
    """The 202 answer to a queued evaluation: its ``Location`` and its body (no result yet)."""
    response.headers["Location"] = api_url(runtime.settings, "evaluations", evaluation.id)
    return evaluations.evaluation_public(
        evaluation, base_url=public_base(runtime.settings), with_result=False
    )


@router.post(
    "/evaluations",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=EvaluationPublic,
    responses=problems(404, 503, 507, examples={422: UNREADABLE}),
)
def create_evaluation_job(
    body: EvaluationCreate,
    response: Response,
    runtime: RuntimeDep,
    project_id: ProjectDep,
) -> EvaluationPublic:
    """Queue an evaluation of uploaded datasets; poll ``GET /evaluations/{id}`` for it."""
    evaluation = evaluations.create_evaluation(runtime, project_id, body)
    return _accepted(evaluation, response, runtime)


@router.post(
    "/ranging",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=EvaluationPublic,
    responses=problems(404, 503, 507, examples={422: UNREADABLE}),
)
def create_ranging_job(
    body: RangingCreate,
    response: Response,
    runtime: RuntimeDep,
    project_id: ProjectDep,
) -> EvaluationPublic:
    """Queue a ranging evaluation of uploaded anchors and ranges against a reference.

    The ranges are evaluated per anchor and the tag is positioned from them (NLLS,
    Min-Max); it runs as an evaluation whose estimates are the solvers: poll
    ``GET /evaluations/{id}``; its result holds the ``ranging`` object.
    """
    evaluation = evaluations.create_ranging(runtime, project_id, body)
    return _accepted(evaluation, response, runtime)


@router.get("/options", response_model=OptionsPublic, responses=problems())
def read_options(_project_id: ProjectDep) -> OptionsPublic:
    """List the options of ``POST /evaluations`` and ``POST /ranging``.

    Key, kind, default, bounds, choices and help of each, from the one table the API's
    schema and the CLI's flags are made from (the browser page builds its form from it).
    """
    return options_public()


@router.get("/evaluations", response_model=EvaluationsPublic, responses=problems())
def read_evaluations(
    runtime: RuntimeDep,
    project_id: ProjectDep,
    status_: Annotated[
        Literal["queued", "running", "succeeded", "failed"] | None, Query(alias="status")
    ] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 100,
    offset: Annotated[int, Query(ge=0, le=1_000_000)] = 0,
) -> EvaluationsPublic:
    """List the project's evaluations, newest first, without their result documents."""
    rows, count = evaluations.list_evaluations(
        runtime, project_id, status=status_, limit=limit, offset=offset
    )
    base = public_base(runtime.settings)
    items = [evaluations.evaluation_public(e, base_url=base, with_result=False) for e in rows]
    return EvaluationsPublic(items=items, count=count)


@router.get(
    "/evaluations/{evaluation_id}", response_model=EvaluationPublic, responses=problems(404)
)
def read_evaluation(
    evaluation_id: PathText, runtime: RuntimeDep, project_id: ProjectDep
) -> EvaluationPublic:
    """Status and progress; the result document once succeeded, the problem once failed."""
    evaluation = get_owned(runtime.sessions, Evaluation, evaluation_id, project_id)
    return evaluations.evaluation_public(
        evaluation, base_url=public_base(runtime.settings), with_result=True
    )


@router.delete(
    "/evaluations/{evaluation_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    responses=problems(404, 409, 507),
)
def delete_evaluation(
    evaluation_id: PathText, runtime: RuntimeDep, project_id: ProjectDep
) -> Response:
    """Delete a finished evaluation and its artifacts (409 while it is queued or running).

    A schedule run that made it keeps its summary report and figures; its row for the
    recording is marked ``evaluation_deleted``.
    """
    retention.delete_evaluation(runtime, project_id, evaluation_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


_ARTIFACT_NOT_READY: Final = problem_example(
    NotReadyError,
    409,
    "Evaluation '297a1e94-c86c-4e41-a598-ddbfae842cde' is running and has not written "
    "'report.pdf' yet; poll GET /evaluations/{id} until its artifacts list it.",
)


@router.get(
    "/evaluations/{evaluation_id}/artifacts/{name}",
    response_class=FileResponse,
    responses={
        200: {
            "description": "the file",
            "content": {spec.media_type: {} for spec in ARTIFACTS.values()},
        },
        **problems(404, 409, examples={409: _ARTIFACT_NOT_READY}),
    },
)
def read_artifact(
    evaluation_id: PathText, name: PathText, runtime: RuntimeDep, project_id: ProjectDep
) -> Response:
    """Download an artifact: report.html, report.pdf, errors.csv, result.json, paths.*."""
    key, filename = evaluations.artifact_path(runtime, project_id, evaluation_id, name)
    return download_response(
        runtime.store,
        key,
        media_type=ARTIFACTS[name].media_type,
        filename=filename,
        inline=name in _INLINE,
    )


_NO_ESTIMATES: Final = problem_example(
    UploadError,
    400,
    "Name the estimates: send 'estimate' files, or 'estimate_selector' values when the "
    "reference file holds them (a bag).",
)
"""The answer to a one-shot request that names no estimate."""

_ONE_SHOT_BODY = {
    "required": True,
    "content": {
        "multipart/form-data": {
            "schema": {
                "type": "object",
                "required": ["reference"],
                "description": "one of 'estimate' (files) or 'estimate_selector' (the "
                "estimates in the reference file, a bag) is needed; with neither the answer is "
                "400",
                "anyOf": [{"required": ["estimate"]}, {"required": ["estimate_selector"]}],
                "additionalProperties": False,
                "properties": {
                    "reference": {"type": "string", "format": "binary"},
                    "estimate": {
                        "type": "array",
                        "items": {"type": "string", "format": "binary"},
                        "description": "omit when the reference file holds the estimates too",
                    },
                    "reference_selector": {"type": "string", "pattern": NO_NUL},
                    "estimate_selector": {
                        "type": "array",
                        "items": {"type": "string", "pattern": NO_NUL},
                    },
                    "estimate_name": {
                        "type": "array",
                        "items": {"type": "string", "pattern": NO_NUL},
                    },
                    "options": {
                        "type": "string",
                        "pattern": NO_NUL,
                        "description": "JSON of the options object",
                    },
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
    responses=problems(400, 404, 413, 503, 507, examples={400: _NO_ESTIMATES, 422: UNREADABLE}),
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
        text_fields=_ONE_SHOT_FIELDS,
        max_files=1 + _MAX_ESTIMATES,
        min_free_bytes=runtime.settings.min_free_bytes,
    )
    try:
        evaluation = await anyio.to_thread.run_sync(
            lambda: evaluations.evaluate_form(runtime, project_id, form)
        )
    finally:
        form.discard()
    count_upload(request, form)
    return _accepted(evaluation, response, runtime)
