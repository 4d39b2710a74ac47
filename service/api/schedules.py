"""``/api/v1/schedules``: recurring summary reports, their runs and their reports."""

from __future__ import annotations

from typing import Annotated, Final

from fastapi import APIRouter, Query, Response, status
from fastapi.responses import FileResponse

from service.api.deps import PathText, ProjectDep, RuntimeDep
from service.api.downloads import download_response
from service.api.links import api_url, public_base
from service.api.responses import not_found, problem_example, problems
from service.db import Schedule, get_owned
from service.errors import NotReadyError
from service.schedules import resource as schedules
from service.schedules.resource import (
    SUMMARY_ARTIFACTS,
    run_public,
    schedule_public,
    schedule_with_secret,
)
from service.schemas.schedules import (
    ScheduleCreate,
    SchedulePatch,
    SchedulePublic,
    ScheduleRunPublic,
    ScheduleRunsPublic,
    SchedulesPublic,
    ScheduleWithSecret,
)

__all__ = ["router"]

router = APIRouter(prefix="/schedules", tags=["schedules"])

_SCHEDULE_ID: Final = "5b0f2a7e-3c41-4d8e-9a6b-1f2e3d4c5b6a"
_EXAMPLES: Final = {404: not_found("schedules", _SCHEDULE_ID)}
_RUN_ARTIFACT: Final = {
    404: _EXAMPLES[404],
    409: problem_example(
        NotReadyError,
        409,
        "Run 'c7e9d1a3-6b2f-4e08-8d5c-2a4b6c8e0f13' is running, so it has no report yet; "
        "poll the run until it succeeds.",
    ),
}


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    response_model=ScheduleWithSecret,
    responses=problems(404, 507),
)
def create_schedule(
    body: ScheduleCreate, response: Response, runtime: RuntimeDep, project_id: ProjectDep
) -> ScheduleWithSecret:
    """Create a schedule: cron and time zone, the recordings it covers, how to evaluate them.

    The answer carries ``webhook_secret``, the key of the signature on each webhook delivery
    (``X-Loceval-Signature``); it is shown only here, so store it. A webhook URL must reach a
    public address unless the administrator allows it (``LOCEVAL_WEBHOOK_ALLOW``).
    """
    schedule = schedules.create_schedule(runtime, project_id, body)
    response.headers["Location"] = api_url(runtime.settings, "schedules", schedule.id)
    return schedule_with_secret(schedule)


@router.get("", response_model=SchedulesPublic, responses=problems())
def read_schedules(runtime: RuntimeDep, project_id: ProjectDep) -> SchedulesPublic:
    """List the project's schedules."""
    rows = schedules.list_schedules(runtime, project_id)
    return SchedulesPublic(items=[schedule_public(s) for s in rows], count=len(rows))


@router.get(
    "/{schedule_id}", response_model=SchedulePublic, responses=problems(404, examples=_EXAMPLES)
)
def read_schedule(
    schedule_id: PathText, runtime: RuntimeDep, project_id: ProjectDep
) -> SchedulePublic:
    """Show a schedule and when it fires next."""
    return schedule_public(get_owned(runtime.sessions, Schedule, schedule_id, project_id))


@router.patch(
    "/{schedule_id}",
    response_model=SchedulePublic,
    responses=problems(404, 507, examples=_EXAMPLES),
)
def update_schedule(
    schedule_id: PathText, body: SchedulePatch, runtime: RuntimeDep, project_id: ProjectDep
) -> SchedulePublic:
    """Pause or resume, change the cron, the selection, the template or the webhook.

    Changing the cron or the time zone, or resuming, counts the next fire from now: fires
    missed while paused are not run. A new webhook URL is checked as on create.
    """
    return schedule_public(schedules.update_schedule(runtime, project_id, schedule_id, body))


@router.post(
    "/{schedule_id}/secret",
    response_model=ScheduleWithSecret,
    responses=problems(404, 507, examples=_EXAMPLES),
)
def rotate_secret(
    schedule_id: PathText, runtime: RuntimeDep, project_id: ProjectDep
) -> ScheduleWithSecret:
    """Replace the webhook signing secret and show the new one (once); the old one stops."""
    return schedule_with_secret(schedules.rotate_secret(runtime, project_id, schedule_id))


@router.delete(
    "/{schedule_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    responses=problems(404, 507, examples=_EXAMPLES),
)
def delete_schedule(schedule_id: PathText, runtime: RuntimeDep, project_id: ProjectDep) -> Response:
    """Delete a schedule with its runs and their reports (the evaluations stay)."""
    schedules.delete_schedule(runtime, project_id, schedule_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.post(
    "/{schedule_id}/run",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=ScheduleRunPublic,
    responses=problems(404, 507, examples=_EXAMPLES),
)
def run_schedule_now(
    schedule_id: PathText, runtime: RuntimeDep, project_id: ProjectDep
) -> ScheduleRunPublic:
    """Start a run now (paused schedules too); poll ``GET .../runs/{run_id}``."""
    schedule = get_owned(runtime.sessions, Schedule, schedule_id, project_id)
    run_id = schedules.trigger_run(runtime, schedule)
    run = schedules.get_run(runtime, project_id, schedule.id, run_id)
    return run_public(run, public_base(runtime.settings))


@router.get(
    "/{schedule_id}/runs",
    response_model=ScheduleRunsPublic,
    responses=problems(404, examples=_EXAMPLES),
)
def read_runs(
    schedule_id: PathText,
    runtime: RuntimeDep,
    project_id: ProjectDep,
    limit: Annotated[int, Query(ge=1, le=500)] = 100,
) -> ScheduleRunsPublic:
    """List a schedule's runs, newest first, with status and links."""
    runs, count = schedules.list_runs(runtime, project_id, schedule_id, limit=limit)
    base = public_base(runtime.settings)
    return ScheduleRunsPublic(items=[run_public(r, base) for r in runs], count=count)


@router.get(
    "/{schedule_id}/runs/{run_id}",
    response_model=ScheduleRunPublic,
    responses=problems(404, examples=_EXAMPLES),
)
def read_run(
    schedule_id: PathText, run_id: PathText, runtime: RuntimeDep, project_id: ProjectDep
) -> ScheduleRunPublic:
    """Show one run."""
    run = schedules.get_run(runtime, project_id, schedule_id, run_id)
    return run_public(run, public_base(runtime.settings))


@router.get(
    "/{schedule_id}/runs/{run_id}/artifacts/{name}",
    response_class=FileResponse,
    responses={
        200: {
            "description": "the summary report",
            "content": {"text/html": {}, "application/pdf": {}},
        },
        **problems(404, 409, examples=_RUN_ARTIFACT),
    },
)
def read_run_artifact(
    schedule_id: PathText,
    run_id: PathText,
    name: PathText,
    runtime: RuntimeDep,
    project_id: ProjectDep,
) -> Response:
    """Download the summary report: summary.html or summary.pdf."""
    key, filename = schedules.run_artifact_path(runtime, project_id, schedule_id, run_id, name)
    return download_response(
        runtime.store,
        key,
        media_type=SUMMARY_ARTIFACTS[name],
        filename=filename,
        inline=True,
    )
