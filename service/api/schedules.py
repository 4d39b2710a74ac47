"""``/api/v1/schedules``: recurring summary reports, their runs and their reports."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query, Request, Response, status
from fastapi.responses import FileResponse
from sqlalchemy import select

from service.api.deps import ProjectDep, RuntimeDep
from service.api.responses import problems
from service.db import Schedule, ScheduleRun, get_owned, utcnow
from service.errors import NotFoundError, NotReadyError
from service.evaluations import check_options
from service.jobs import Runtime
from service.schedules import SUMMARY_ARTIFACTS, check_cron, next_fire, trigger_run
from service.schemas import (
    ArtifactPublic,
    ProgressPublic,
    ScheduleCreate,
    SchedulePatch,
    SchedulePublic,
    ScheduleRunPublic,
    ScheduleRunsPublic,
    SchedulesPublic,
)

__all__ = ["router"]

router = APIRouter(prefix="/schedules", tags=["schedules"])


def _schedule_public(schedule: Schedule) -> SchedulePublic:
    return SchedulePublic.model_validate(schedule, from_attributes=True)


def _run_public(run: ScheduleRun, base_url: str) -> ScheduleRunPublic:
    artifacts = None
    if run.status == "succeeded" and run.artifacts is not None:
        prefix = f"{base_url}api/v1/schedules/{run.schedule_id}/runs/{run.id}/artifacts/"
        artifacts = [ArtifactPublic(**a, url=prefix + a["name"]) for a in run.artifacts]
    return ScheduleRunPublic.model_validate(
        {
            "id": run.id,
            "schedule_id": run.schedule_id,
            "trigger": run.trigger,
            "due_at": run.due_at,
            "status": run.status,
            "progress": ProgressPublic(stage=run.stage, fraction=run.fraction),
            "note": run.note,
            "rows": run.rows,
            "error": run.error,
            "artifacts": artifacts,
            "webhook": run.webhook,
            "attempts": run.attempts,
            "created_at": run.created_at,
            "started_at": run.started_at,
            "finished_at": run.finished_at,
        }
    )


def _get_run(runtime: Runtime, project_id: str, schedule_id: str, run_id: str) -> ScheduleRun:
    get_owned(runtime.sessions, Schedule, schedule_id, project_id)
    with runtime.sessions() as session:
        run = session.get(ScheduleRun, run_id)
    if run is None or run.schedule_id != schedule_id:
        msg = f"No run {run_id!r} of schedule {schedule_id!r}; list them with GET .../runs."
        raise NotFoundError(msg)
    return run


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    response_model=SchedulePublic,
    responses=problems(),
)
def create_schedule(
    body: ScheduleCreate, request: Request, response: Response, runtime: RuntimeDep,
    project_id: ProjectDep,
) -> SchedulePublic:  # fmt: skip
    """Create a schedule: cron and time zone, the recordings it covers, how to evaluate them."""
    check_cron(body.cron, body.timezone)
    check_options(body.template.options)
    now = utcnow()
    schedule = Schedule(
        project_id=project_id,
        name=body.name,
        cron=body.cron,
        timezone=body.timezone,
        paused=body.paused,
        selection=body.selection.model_dump(mode="json"),
        template=body.template.model_dump(mode="json"),
        produce=body.produce.model_dump(mode="json"),
        webhook_url=body.webhook_url,
        next_fire_at=next_fire(body.cron, body.timezone, now),
        created_at=now,
        updated_at=now,
    )
    with runtime.sessions() as session:
        session.add(schedule)
        session.commit()
    response.headers["Location"] = f"{request.base_url}api/v1/schedules/{schedule.id}"
    return _schedule_public(schedule)


@router.get("", response_model=SchedulesPublic, responses=problems())
def read_schedules(runtime: RuntimeDep, project_id: ProjectDep) -> SchedulesPublic:
    """List the project's schedules."""
    with runtime.sessions() as session:
        rows = session.scalars(
            select(Schedule)
            .where(Schedule.project_id == project_id)
            .order_by(Schedule.created_at, Schedule.id)
        ).all()
    return SchedulesPublic(items=[_schedule_public(s) for s in rows], count=len(rows))


@router.get("/{schedule_id}", response_model=SchedulePublic, responses=problems(404))
def read_schedule(schedule_id: str, runtime: RuntimeDep, project_id: ProjectDep) -> SchedulePublic:
    """Show a schedule and when it fires next."""
    return _schedule_public(get_owned(runtime.sessions, Schedule, schedule_id, project_id))


@router.patch("/{schedule_id}", response_model=SchedulePublic, responses=problems(404))
def update_schedule(
    schedule_id: str, body: SchedulePatch, runtime: RuntimeDep, project_id: ProjectDep
) -> SchedulePublic:
    """Pause or resume, change the cron, the selection, the template or the webhook.

    Changing the cron or the time zone, or resuming, counts the next fire from now: fires
    missed while paused are not run.
    """
    schedule = get_owned(runtime.sessions, Schedule, schedule_id, project_id)
    changes = body.model_dump(exclude_unset=True, mode="json")
    cron = changes.get("cron", schedule.cron)
    timezone = changes.get("timezone", schedule.timezone)
    check_cron(cron, timezone)
    if body.template is not None:
        check_options(body.template.options)
    now = utcnow()
    resumed = schedule.paused and changes.get("paused") is False
    if resumed or "cron" in changes or "timezone" in changes:
        changes["next_fire_at"] = next_fire(cron, timezone, now)
    with runtime.sessions() as session:
        row = session.get_one(Schedule, schedule.id)
        for key, value in changes.items():
            setattr(row, key, value)
        row.updated_at = now
        session.commit()
    return _schedule_public(row)


@router.delete("/{schedule_id}", status_code=status.HTTP_204_NO_CONTENT, responses=problems(404))
def delete_schedule(schedule_id: str, runtime: RuntimeDep, project_id: ProjectDep) -> Response:
    """Delete a schedule with its runs and their reports (the evaluations stay)."""
    schedule = get_owned(runtime.sessions, Schedule, schedule_id, project_id)
    with runtime.sessions() as session:
        run_ids = session.scalars(
            select(ScheduleRun.id).where(ScheduleRun.schedule_id == schedule.id)
        ).all()
        for run in session.scalars(
            select(ScheduleRun).where(ScheduleRun.schedule_id == schedule.id)
        ):
            session.delete(run)
        session.delete(session.get_one(Schedule, schedule.id))
        session.commit()
    for run_id in run_ids:
        runtime.store.remove_run(run_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.post(
    "/{schedule_id}/run",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=ScheduleRunPublic,
    responses=problems(404),
)
def run_schedule_now(
    schedule_id: str, request: Request, runtime: RuntimeDep, project_id: ProjectDep
) -> ScheduleRunPublic:
    """Start a run now (paused schedules too); poll ``GET .../runs/{run_id}``."""
    schedule = get_owned(runtime.sessions, Schedule, schedule_id, project_id)
    run_id = trigger_run(runtime, schedule)
    return _run_public(_get_run(runtime, project_id, schedule.id, run_id), str(request.base_url))


@router.get("/{schedule_id}/runs", response_model=ScheduleRunsPublic, responses=problems(404))
def read_runs(
    schedule_id: str,
    request: Request,
    runtime: RuntimeDep,
    project_id: ProjectDep,
    limit: Annotated[int, Query(ge=1, le=500)] = 100,
) -> ScheduleRunsPublic:
    """List a schedule's runs, newest first, with status and links."""
    schedule = get_owned(runtime.sessions, Schedule, schedule_id, project_id)
    with runtime.sessions() as session:
        runs = session.scalars(
            select(ScheduleRun)
            .where(ScheduleRun.schedule_id == schedule.id)
            .order_by(ScheduleRun.due_at.desc(), ScheduleRun.id)
        ).all()
    base = str(request.base_url)
    return ScheduleRunsPublic(items=[_run_public(r, base) for r in runs[:limit]], count=len(runs))


@router.get(
    "/{schedule_id}/runs/{run_id}", response_model=ScheduleRunPublic, responses=problems(404)
)
def read_run(
    schedule_id: str, run_id: str, request: Request, runtime: RuntimeDep, project_id: ProjectDep
) -> ScheduleRunPublic:
    """Show one run."""
    return _run_public(_get_run(runtime, project_id, schedule_id, run_id), str(request.base_url))


@router.get(
    "/{schedule_id}/runs/{run_id}/artifacts/{name}",
    response_class=FileResponse,
    responses={
        200: {
            "description": "the summary report",
            "content": {"text/html": {}, "application/pdf": {}},
        },
        **problems(404, 409),
    },
)
def read_run_artifact(
    schedule_id: str, run_id: str, name: str, runtime: RuntimeDep, project_id: ProjectDep
) -> FileResponse:
    """Download the summary report: summary.html or summary.pdf."""
    run = _get_run(runtime, project_id, schedule_id, run_id)
    if name not in SUMMARY_ARTIFACTS:
        msg = f"No artifact {name!r}; a run has {', '.join(SUMMARY_ARTIFACTS)}."
        raise NotFoundError(msg)
    if run.status != "succeeded":
        msg = f"Run {run_id!r} is {run.status}, so it has no report" + (
            " yet; poll the run until it succeeds." if run.status in {"queued", "running"}
            else "; see its error."
        )  # fmt: skip
        raise NotReadyError(msg)
    path = runtime.store.run_artifacts_dir(run.id) / name
    if not path.is_file():
        msg = f"Run {run_id!r} did not write {name!r} (the schedule's formats left it out)."
        raise NotFoundError(msg)
    return FileResponse(
        path,
        media_type=SUMMARY_ARTIFACTS[name],
        filename=f"loceval-run-{run.id[:8]}-{name}",
        content_disposition_type="inline",
    )
