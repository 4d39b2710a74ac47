"""The schedules resource: recurring summary reports, when they fire, and their runs.

A schedule fires from the queue's periodic tick (every consumer process ticks once a minute,
and once on start). :func:`tick` moves a due schedule's ``next_fire_at`` forward with a
conditional update, so of several processes ticking at once exactly one wins and records the
run (a unique ``(schedule, due time)`` backs this up). A fire missed while the service was
down is run once, late, and the run says so. What a run does is in
:mod:`service.schedules.runs`; the routes in :mod:`service.api.schedules` call the functions
here.
"""

from __future__ import annotations

import datetime as dt
import fnmatch
import logging
import re
import zoneinfo
from collections.abc import Mapping, Sequence
from typing import Any, Final

from croniter import CroniterBadCronError, croniter
from sqlalchemy import func, select, update
from sqlalchemy.exc import IntegrityError

from loceval.errors import InputError
from service.blobs import artifact_key
from service.blobs.base import RUNS, download_filename
from service.db import (
    ACTIVE_STATUSES,
    Dataset,
    JobStatus,
    Schedule,
    ScheduleRun,
    get_owned,
    new_id,
    utcnow,
)
from service.errors import NotFoundError, NotReadyError
from service.jobs.evaluations import check_options
from service.jobs.kinds import RUN
from service.runtime import Runtime
from service.schemas.evaluations import ArtifactPublic, ProgressPublic
from service.schemas.schedules import (
    CRON_PATTERN,
    TIME_ZONES,
    ScheduleCreate,
    SchedulePatch,
    SchedulePublic,
    ScheduleRunPublic,
    ScheduleWithSecret,
    Selection,
)
from service.uploads.evo_results import check_evo_results
from service.webhooks import AllowList, check_webhook_url, new_secret

__all__ = [
    "SUMMARY_ARTIFACTS",
    "check_cron",
    "create_schedule",
    "delete_schedule",
    "describe_selection",
    "get_run",
    "list_runs",
    "list_schedules",
    "next_fire",
    "rotate_secret",
    "run_artifact_filename",
    "run_artifact_path",
    "run_public",
    "schedule_public",
    "schedule_with_secret",
    "select_datasets",
    "tick",
    "trigger_run",
    "update_schedule",
]

logger = logging.getLogger(__name__)

_LATE: Final = dt.timedelta(seconds=90)  # a fire found later than this was missed
_MAX_COUNTED_MISSES: Final = 10_000
SUMMARY_ARTIFACTS: Final = {"summary.html": "text/html", "summary.pdf": "application/pdf"}


def check_cron(cron: str, timezone: str) -> None:
    """Check a cron expression and a time zone name.

    Raises:
        InputError: the expression or the zone is not valid (the message says why).
    """
    if timezone not in TIME_ZONES:  # ZoneInfo would take more (file names, "localtime")
        msg = f"Unknown time zone {timezone!r}; use an IANA name such as 'Europe/Berlin' or 'UTC'."
        raise InputError(msg)
    if (
        not croniter.is_valid(cron)
        or len(cron.split()) != 5
        or not re.fullmatch(CRON_PATTERN, cron)
    ):
        msg = (
            f"Invalid cron expression {cron!r}; give five fields 'minute hour day month "
            "weekday', e.g. '0 7 * * mon' for Mondays at 07:00."
        )
        raise InputError(msg)


def next_fire(cron: str, timezone: str, after: dt.datetime) -> dt.datetime:
    """Return the first fire time strictly after ``after`` (aware UTC), in the zone's clock."""
    check_cron(cron, timezone)
    zone = zoneinfo.ZoneInfo(timezone)
    try:
        fire: dt.datetime = croniter(cron, after.astimezone(zone)).get_next(dt.datetime)
    except CroniterBadCronError as err:  # pragma: no cover  (checked above)
        msg = f"Invalid cron expression {cron!r} ({err})."
        raise InputError(msg) from err
    return fire.astimezone(dt.UTC)


def _missed_fires(cron: str, timezone: str, due: dt.datetime, now: dt.datetime) -> int:
    """Count the fire times in ``(due, now]`` (bounded), i.e. fires skipped by one late run."""
    zone = zoneinfo.ZoneInfo(timezone)
    it = croniter(cron, due.astimezone(zone))
    count = 0
    while count < _MAX_COUNTED_MISSES and it.get_next(dt.datetime) <= now:
        count += 1
    return count


# --- firing ---------------------------------------------------------------------------


def tick(runtime: Runtime, now: dt.datetime | None = None) -> list[str]:
    """Record and queue a run for every schedule due at ``now``; return the run ids.

    Safe to call from many processes at once: each due time becomes exactly one run.
    """
    now = now or utcnow()
    fired: list[str] = []
    with runtime.sessions() as session:
        due = session.scalars(
            select(Schedule).where(Schedule.paused.is_(False), Schedule.next_fire_at <= now)
        ).all()
    for schedule in due:
        run_id = _fire(runtime, schedule, now)
        if run_id is not None:
            fired.append(run_id)
    for run_id in fired:
        runtime.enqueue(RUN, run_id)
    return fired


def _fire(runtime: Runtime, schedule: Schedule, now: dt.datetime) -> str | None:
    due = schedule.next_fire_at
    assert due is not None  # noqa: S101  (selected by next_fire_at <= now)
    try:
        following = next_fire(schedule.cron, schedule.timezone, now)
    except InputError:
        logger.exception("Schedule %s has an unusable cron; pausing it", schedule.id)
        following = None
    late = now - due > _LATE
    note = None
    if late:
        skipped = _missed_fires(schedule.cron, schedule.timezone, due, now)
        note = (
            f"The service was not running at {due:%Y-%m-%d %H:%M} UTC; this run was started "
            f"late, at {now:%Y-%m-%d %H:%M} UTC"
            + (f", and stands for {skipped + 1} missed fires." if skipped else ".")
        )
    run = ScheduleRun(
        id=new_id(),
        schedule_id=schedule.id,
        project_id=schedule.project_id,
        trigger="missed" if late else "cron",
        due_at=due,
        note=note,
        created_at=now,
    )
    with runtime.sessions() as session:
        won = session.execute(
            update(Schedule)
            .where(Schedule.id == schedule.id, Schedule.next_fire_at == due)
            .values(
                next_fire_at=following,
                last_fired_at=due,
                paused=following is None,
            )
        )
        if not won.rowcount:  # type: ignore[attr-defined]
            session.rollback()
            return None  # another process fired it
        session.add(run)
        try:
            session.commit()
        except IntegrityError:
            session.rollback()
            return None
    if late:
        logger.warning("Schedule %s: %s", schedule.id, note)
    return run.id


def trigger_run(runtime: Runtime, schedule: Schedule, *, now: dt.datetime | None = None) -> str:
    """Record and queue a run of a schedule now (``POST /schedules/{id}/run``)."""
    now = now or utcnow()
    run = ScheduleRun(
        id=new_id(),
        schedule_id=schedule.id,
        project_id=schedule.project_id,
        trigger="manual",
        due_at=now,
        created_at=now,
    )
    with runtime.sessions() as session:
        session.add(run)
        session.commit()
    runtime.enqueue(RUN, run.id)
    return run.id


# --- selecting recordings ---------------------------------------------------------------


def _selection(selection: Selection | Mapping[str, Any]) -> Selection:
    """Return a stored selection re-validated into its model."""
    return selection if isinstance(selection, Selection) else Selection.model_validate(selection)


def select_datasets(
    datasets: Sequence[Dataset], selection: Selection | Mapping[str, Any], *, as_of: dt.datetime
) -> list[Dataset]:
    """Return the datasets a selection picks, oldest first.

    A selection has ``tags`` (all must be present), ``name_pattern`` (a shell pattern,
    case-insensitive, matched against the name and the file name) and
    ``uploaded_within_days`` (counted back from ``as_of``); a missing key selects all.
    Recordings uploaded after ``as_of`` are not included. Uploaded evo result zips the
    conditions match are picked like recordings (a run takes their figures); the zips named
    in ``evo_results`` are added by the run (:mod:`service.schedules.runs`).
    """
    chosen = _selection(selection)
    tags = set(chosen.tags)
    pattern = (chosen.name_pattern or "").lower()
    days = chosen.uploaded_within_days
    since = as_of - dt.timedelta(days=days) if days is not None else None
    picked = [
        d
        for d in datasets
        if d.inspection.get("format") not in {None, "urdf"}
        and tags <= set(d.tags)
        and (
            not pattern
            or fnmatch.fnmatchcase(d.name.lower(), pattern)
            or fnmatch.fnmatchcase(d.filename.lower(), pattern)
        )
        and d.created_at <= as_of
        and (since is None or d.created_at >= since)
    ]
    return sorted(picked, key=lambda d: (d.created_at, d.id))


def describe_selection(selection: Selection | Mapping[str, Any], *, as_of: dt.datetime) -> str:
    """Return the selection in words, for the report and the webhook."""
    chosen = _selection(selection)
    parts = ["recordings"]
    if chosen.tags:
        parts.append("tagged " + ", ".join(repr(t) for t in chosen.tags))
    if chosen.name_pattern:
        parts.append(f"named like {chosen.name_pattern!r}")
    if chosen.uploaded_within_days is not None:
        days = chosen.uploaded_within_days
        parts.append(f"uploaded in the {days:g} days before {as_of:%Y-%m-%d %H:%M} UTC")
    else:
        parts.append(f"uploaded before {as_of:%Y-%m-%d %H:%M} UTC")
    named = len(chosen.evo_results)
    if named:
        parts.append(f"and {named} evo result zip{'s' if named > 1 else ''} named by id")
    return " ".join(parts)


# --- the resource ------------------------------------------------------------------------


def schedule_public(schedule: Schedule) -> SchedulePublic:
    """Return the HTTP view of a schedule."""
    return SchedulePublic.model_validate(schedule, from_attributes=True)


def run_public(run: ScheduleRun, base_url: str) -> ScheduleRunPublic:
    """Return the HTTP view of a run, with links to its reports once it succeeded."""
    artifacts = None
    if run.status == JobStatus.SUCCEEDED and run.artifacts is not None:
        prefix = f"{base_url}api/v1/schedules/{run.schedule_id}/runs/{run.id}/artifacts/"
        artifacts = [
            ArtifactPublic(
                **a, url=prefix + a["name"], filename=run_artifact_filename(run, a["name"])
            )
            for a in run.artifacts
        ]
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


def schedule_with_secret(schedule: Schedule) -> ScheduleWithSecret:
    """Return the HTTP view of a schedule with its signing secret (create and rotate only)."""
    return ScheduleWithSecret.model_validate(schedule, from_attributes=True)


def _check_webhook(runtime: Runtime, url: str | None) -> None:
    """Refuse a webhook URL that is not http(s) or points at an internal address.

    Raises:
        WebhookRefusedError: the URL is refused (the message names webhook_url and says
            what to do); a subclass of InputError, so a 422 problem.
    """
    if url is not None:
        check_webhook_url(url, AllowList.parse(runtime.settings.webhook_allow))


def _check_baseline(runtime: Runtime, project_id: str, baseline: str | None) -> None:
    """A pinned baseline (``template.options.baseline``) is a succeeded evaluation of the project.

    Every run compares its evaluation with it (:mod:`service.jobs.baseline`), and the
    run's summary shows each run against it.

    Raises:
        NotFoundError: no such evaluation in the project.
        InputError: it has not succeeded.
    """
    if baseline is None:
        return
    from service.jobs.baseline import evaluation_baseline  # noqa: PLC0415

    evaluation_baseline(runtime, project_id, baseline)


def create_schedule(runtime: Runtime, project_id: str, body: ScheduleCreate) -> Schedule:
    """Check and record a new schedule; it fires first at the cron's next time.

    The schedule gets its webhook signing secret here; only the create answer shows it.

    Raises:
        InputError: the cron, the time zone, an option of the template, a named evo
            result or the webhook URL is not usable.
    """
    check_cron(body.cron, body.timezone)
    check_options(body.template.options)
    _check_baseline(runtime, project_id, body.template.options.baseline)
    check_evo_results(runtime, project_id, body.selection.evo_results)
    _check_webhook(runtime, body.webhook_url)
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
        webhook_secret=new_secret(),
        next_fire_at=next_fire(body.cron, body.timezone, now),
        created_at=now,
        updated_at=now,
    )
    with runtime.sessions() as session:
        session.add(schedule)
        session.commit()
    return schedule


def list_schedules(runtime: Runtime, project_id: str) -> Sequence[Schedule]:
    """Return the project's schedules, oldest first."""
    with runtime.sessions() as session:
        return session.scalars(
            select(Schedule)
            .where(Schedule.project_id == project_id)
            .order_by(Schedule.created_at, Schedule.id)
        ).all()


def update_schedule(
    runtime: Runtime, project_id: str, schedule_id: str, body: SchedulePatch
) -> Schedule:
    """Apply a patch; a changed cron or zone, or resuming, counts the next fire from now.

    Raises:
        NotFoundError: no such schedule in the project.
        InputError: the cron, the time zone, an option of the template or the webhook URL
            is not usable.
    """
    schedule = get_owned(runtime.sessions, Schedule, schedule_id, project_id)
    changes = body.model_dump(exclude_unset=True, mode="json")
    cron = changes.get("cron", schedule.cron)
    timezone = changes.get("timezone", schedule.timezone)
    check_cron(cron, timezone)
    if body.template is not None:
        check_options(body.template.options)
        _check_baseline(runtime, project_id, body.template.options.baseline)
    if body.selection is not None:
        check_evo_results(runtime, project_id, body.selection.evo_results)
    _check_webhook(runtime, changes.get("webhook_url"))
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
    return row


def rotate_secret(runtime: Runtime, project_id: str, schedule_id: str) -> Schedule:
    """Give a schedule a new webhook signing secret; the old one stops verifying at once.

    Raises:
        NotFoundError: no such schedule in the project.
    """
    schedule = get_owned(runtime.sessions, Schedule, schedule_id, project_id)
    with runtime.sessions() as session:
        row = session.get_one(Schedule, schedule.id)
        row.webhook_secret = new_secret()
        row.updated_at = utcnow()
        session.commit()
    return row


def delete_schedule(runtime: Runtime, project_id: str, schedule_id: str) -> None:
    """Delete a schedule with its runs and their reports (the evaluations stay).

    Raises:
        NotFoundError: no such schedule in the project.
    """
    schedule = get_owned(runtime.sessions, Schedule, schedule_id, project_id)
    with runtime.sessions() as session:
        runs = session.scalars(
            select(ScheduleRun).where(ScheduleRun.schedule_id == schedule.id)
        ).all()
        run_ids = [run.id for run in runs]
        for run in runs:
            session.delete(run)
        session.delete(session.get_one(Schedule, schedule.id))
        session.commit()
    for run_id in run_ids:
        runtime.store.remove_job(RUNS, run_id)


def list_runs(
    runtime: Runtime, project_id: str, schedule_id: str, *, limit: int
) -> tuple[Sequence[ScheduleRun], int]:
    """Return the newest ``limit`` runs of a schedule and how many it has.

    Raises:
        NotFoundError: no such schedule in the project.
    """
    schedule = get_owned(runtime.sessions, Schedule, schedule_id, project_id)
    where = ScheduleRun.schedule_id == schedule.id
    with runtime.sessions() as session:
        count = session.scalar(select(func.count()).select_from(ScheduleRun).where(where))
        runs = session.scalars(
            select(ScheduleRun)
            .where(where)
            .order_by(ScheduleRun.due_at.desc(), ScheduleRun.id)
            .limit(limit)
        ).all()
    return runs, int(count or 0)


def get_run(runtime: Runtime, project_id: str, schedule_id: str, run_id: str) -> ScheduleRun:
    """Return a run of a schedule of the project.

    Raises:
        NotFoundError: no such schedule in the project, or no such run of it.
    """
    get_owned(runtime.sessions, Schedule, schedule_id, project_id)
    with runtime.sessions() as session:
        run = session.get(ScheduleRun, run_id)
    if run is None or run.schedule_id != schedule_id:
        msg = f"No run {run_id!r} of schedule {schedule_id!r}; list them with GET .../runs."
        raise NotFoundError(msg)
    return run


def run_artifact_filename(run: ScheduleRun, name: str) -> str:
    """Return the name a run's report is saved under: ``run-<day due>-<id>-<name>``."""
    return download_filename(f"run-{run.due_at:%Y-%m-%d}-{run.id[:8]}", name, default=run.id)


def run_artifact_path(
    runtime: Runtime, project_id: str, schedule_id: str, run_id: str, name: str
) -> tuple[str, str]:
    """Return the blob key of a run's summary report and the name it is saved under.

    The reports are summary.html and summary.pdf.

    Raises:
        NotFoundError: no such run, report name, or file (the schedule's formats left it out).
        NotReadyError: the run has not succeeded.
    """
    run = get_run(runtime, project_id, schedule_id, run_id)
    if name not in SUMMARY_ARTIFACTS:
        msg = f"No artifact {name!r}; a run has {', '.join(SUMMARY_ARTIFACTS)}."
        raise NotFoundError(msg)
    if run.status != JobStatus.SUCCEEDED:
        msg = f"Run {run_id!r} is {run.status}, so it has no report" + (
            " yet; poll the run until it succeeds." if run.status in ACTIVE_STATUSES
            else "; see its error."
        )  # fmt: skip
        raise NotReadyError(msg)
    key = artifact_key(RUNS, run.id, name)
    if not runtime.store.exists(key):
        msg = f"Run {run_id!r} did not write {name!r} (the schedule's formats left it out)."
        raise NotFoundError(msg)
    return key, run_artifact_filename(run, name)
