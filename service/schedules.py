"""Scheduled summary reports: when schedules fire, and what one run does.

A schedule fires from the queue's periodic tick (every consumer process ticks once a minute,
and once on start). :func:`tick` moves a due schedule's ``next_fire_at`` forward with a
conditional update, so of several processes ticking at once exactly one wins and records the
run (a unique ``(schedule, due time)`` backs this up). A fire missed while the service was
down is run once, late, and the run says so. A run evaluates every selected recording with
the schedule's template (as evaluation jobs, listed with the others), then renders one
summary report and, if asked, posts a JSON summary to a webhook.
"""

from __future__ import annotations

import datetime as dt
import fnmatch
import json
import logging
import shutil
import time
import urllib.error
import urllib.request
import zoneinfo
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final

import numpy as np
from croniter import CroniterBadCronError, croniter
from sqlalchemy import select, update
from sqlalchemy.exc import IntegrityError

from loceval.errors import InputError, LocevalError
from loceval.evaluation import Tolerance
from loceval.readers import SourceSpec, TrajectoryFormat, read_trajectory
from service.db import (
    Dataset,
    Evaluation,
    EvaluationStatus,
    Schedule,
    ScheduleRun,
    new_id,
    utcnow,
)
from service.errors import internal_problem, problem_for
from service.jobs import (
    Heartbeat,
    ProgressWriter,
    Runtime,
    claim,
    execute_evaluation,
    finish,
)

__all__ = [
    "SUMMARY_ARTIFACTS",
    "check_cron",
    "describe_selection",
    "execute_schedule_run",
    "next_fire",
    "select_datasets",
    "tick",
    "trigger_run",
    "webhook_payload",
]

logger = logging.getLogger(__name__)

_LATE: Final = dt.timedelta(seconds=90)  # a fire found later than this was missed
_MAX_COUNTED_MISSES: Final = 10_000
_WEBHOOK_ATTEMPTS: Final = 3
_WEBHOOK_TIMEOUT_S: Final = 10.0
SUMMARY_ARTIFACTS: Final = {"summary.html": "text/html", "summary.pdf": "application/pdf"}


def check_cron(cron: str, timezone: str) -> None:
    """Check a cron expression and a time zone name.

    Raises:
        InputError: the expression or the zone is not valid (the message says why).
    """
    try:
        zoneinfo.ZoneInfo(timezone)
    except (zoneinfo.ZoneInfoNotFoundError, ValueError):
        msg = f"Unknown time zone {timezone!r}; use an IANA name such as 'Europe/Berlin' or 'UTC'."
        raise InputError(msg) from None
    if not croniter.is_valid(cron) or len(cron.split()) != 5:
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
        runtime.enqueue_schedule_run(run_id)
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
    runtime.enqueue_schedule_run(run.id)
    return run.id


# --- selecting recordings ---------------------------------------------------------------


def select_datasets(
    datasets: Sequence[Dataset], selection: Mapping[str, Any], *, as_of: dt.datetime
) -> list[Dataset]:
    """Return the datasets a selection picks, oldest first.

    A selection has ``tags`` (all must be present), ``name_pattern`` (a shell pattern,
    case-insensitive, matched against the name and the file name) and
    ``uploaded_within_days`` (counted back from ``as_of``); a missing key selects all.
    Recordings uploaded after ``as_of`` are not included.
    """
    tags = set(selection.get("tags") or [])
    pattern = (selection.get("name_pattern") or "").lower()
    days = selection.get("uploaded_within_days")
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


def describe_selection(selection: Mapping[str, Any], *, as_of: dt.datetime) -> str:
    """Return the selection in words, for the report and the webhook."""
    parts = ["recordings"]
    if selection.get("tags"):
        parts.append("tagged " + ", ".join(repr(t) for t in selection["tags"]))
    if selection.get("name_pattern"):
        parts.append(f"named like {selection['name_pattern']!r}")
    days = selection.get("uploaded_within_days")
    if days is not None:
        parts.append(f"uploaded in the {days:g} days before {as_of:%Y-%m-%d %H:%M} UTC")
    else:
        parts.append(f"uploaded before {as_of:%Y-%m-%d %H:%M} UTC")
    return " ".join(parts)


# --- one run ----------------------------------------------------------------------------


def execute_schedule_run(runtime: Runtime, run_id: str) -> None:
    """Evaluate the selected recordings, render the summary and notify; never raises."""
    if not claim(runtime, ScheduleRun, run_id, stage="selecting recordings"):
        return
    heartbeat = Heartbeat(runtime, ScheduleRun, run_id)
    heartbeat.start()
    staging: Path | None = None
    try:
        run, schedule, datasets = _load(runtime, run_id)
        picked = select_datasets(datasets, schedule.selection, as_of=run.due_at)
        progress = ProgressWriter(runtime, ScheduleRun, run_id)
        rows, summary_runs = _evaluate_all(runtime, run, schedule, picked, progress)
        staging = runtime.store.run_staging_dir(run_id)
        progress("writing the summary report", 0.85)
        _render(run, schedule, summary_runs, staging, runtime.settings.templates_dir)
        artifacts = _publish(runtime, run_id, staging)
        staging = None
        finish(
            runtime,
            ScheduleRun,
            run_id,
            status=EvaluationStatus.SUCCEEDED,
            rows=rows,
            artifacts=artifacts,
        )
    except LocevalError as err:
        body = problem_for(err)
        body["detail"] = runtime.store.scrub(body["detail"])
        finish(runtime, ScheduleRun, run_id, status=EvaluationStatus.FAILED, error=body)
    except Exception:
        error_id = new_id()[:12]
        logger.exception("Schedule run %s failed with a bug (error_id=%s)", run_id, error_id)
        finish(
            runtime,
            ScheduleRun,
            run_id,
            status=EvaluationStatus.FAILED,
            error=internal_problem(error_id),
        )
    finally:
        heartbeat.stop()
        if staging is not None:
            shutil.rmtree(staging, ignore_errors=True)
    _notify(runtime, run_id)


def _load(runtime: Runtime, run_id: str) -> tuple[ScheduleRun, Schedule, Sequence[Dataset]]:
    with runtime.sessions() as session:
        run = session.get_one(ScheduleRun, run_id)
        schedule = session.get(Schedule, run.schedule_id)
        if schedule is None:
            msg = "The schedule was deleted before its run started."
            raise InputError(msg)
        datasets = session.scalars(select(Dataset).where(Dataset.project_id == run.project_id))
        return run, schedule, datasets.all()


def _evaluate_all(
    runtime: Runtime,
    run: ScheduleRun,
    schedule: Schedule,
    picked: Sequence[Dataset],
    progress: ProgressWriter,
) -> tuple[list[dict[str, Any]], list[Any]]:
    """Run the template on every picked recording; failures become rows with the reason."""
    from exporters.summary import SummaryRun  # noqa: PLC0415
    from service.evaluations import create_evaluation  # noqa: PLC0415
    from service.schemas import EvaluationCreate  # noqa: PLC0415

    template = schedule.template
    per_run = bool(schedule.produce.get("per_run_artifacts"))
    rows: list[dict[str, Any]] = []
    summary_runs = []
    for k, dataset in enumerate(picked):
        progress(f"evaluating {dataset.name}", 0.8 * k / max(len(picked), 1))
        row: dict[str, Any] = {"dataset_id": dataset.id, "dataset": dataset.name}
        options = dict(template.get("options") or {})
        if not per_run:
            options["formats"] = ["result.json"]
        body = EvaluationCreate.model_validate(
            {
                "reference": {**template["reference"], "dataset_id": dataset.id},
                "estimates": [{**e, "dataset_id": dataset.id} for e in template["estimates"]],
                "options": options,
            }
        )
        try:
            evaluation = create_evaluation(runtime, run.project_id, body, enqueue=False)
        except LocevalError as err:
            reason = runtime.store.scrub(str(err))
            rows.append({**row, "status": "failed", "error": reason, "evaluation_id": None})
            summary_runs.append(_failed_run(dataset, reason))
            continue
        execute_evaluation(runtime, evaluation.id)
        with runtime.sessions() as session:
            done = session.get_one(Evaluation, evaluation.id)
        row["evaluation_id"] = done.id
        if done.status != EvaluationStatus.SUCCEEDED or done.result is None:
            reason = (done.error or {}).get("detail", "The evaluation did not finish.")
            rows.append({**row, "status": "failed", "error": reason})
            summary_runs.append(_failed_run(dataset, reason, done.id))
            continue
        rows.append({**row, "status": "succeeded", "error": None, "summary": done.summary})
        summary_runs.append(
            SummaryRun.from_result(
                done.result,
                dataset=dataset.name,
                recorded_at=dataset.created_at,
                evaluation_id=done.id,
                reference_xyz=_reference_xyz(runtime, dataset, template),
            )
        )
    return rows, summary_runs


def _failed_run(dataset: Dataset, reason: str, evaluation_id: str | None = None) -> Any:  # noqa: ANN401
    from exporters.summary import SummaryRun  # noqa: PLC0415

    return SummaryRun(
        dataset=dataset.name,
        recorded_at=dataset.created_at,
        status="failed",
        error=reason,
        evaluation_id=evaluation_id,
    )


def _reference_xyz(
    runtime: Runtime, dataset: Dataset, template: Mapping[str, Any]
) -> np.ndarray[Any, np.dtype[np.float64]] | None:
    """Re-read the run's reference path for the repeatability table (None if unreadable)."""
    fmt = dataset.inspection.get("format")
    try:
        spec = SourceSpec(
            TrajectoryFormat(str(fmt)),
            runtime.store.path(dataset.storage_path),
            template["reference"].get("selector"),
        )
        stamp = (template.get("options") or {}).get("stamp", "header")
        return read_trajectory(spec, stamp=stamp).positions_xyz
    except (LocevalError, ValueError):
        return None


def _render(
    run: ScheduleRun,
    schedule: Schedule,
    summary_runs: Sequence[Any],
    staging: Path,
    templates_dir: Path,
) -> None:
    from exporters.summary import SummaryInput, render_summary  # noqa: PLC0415

    tolerance = (schedule.template.get("options") or {}).get("tolerance")
    notes = [run.note] if run.note else []
    summary = SummaryInput(
        title=schedule.name,
        generated_at=utcnow(),
        selection=describe_selection(schedule.selection, as_of=run.due_at),
        runs=summary_runs,
        tolerance=Tolerance.parse(tolerance) if tolerance else None,
        notes=notes,
        schedule_id=schedule.id,
        run_id=run.id,
    )
    html, pdf = render_summary(summary, templates_dir=templates_dir)
    wanted = schedule.produce.get("summary_formats") or list(SUMMARY_ARTIFACTS)
    staging.mkdir(parents=True, exist_ok=True)
    if "summary.html" in wanted:
        (staging / "summary.html").write_bytes(html)
    if "summary.pdf" in wanted:
        (staging / "summary.pdf").write_bytes(pdf)


def _publish(runtime: Runtime, run_id: str, staging: Path) -> list[dict[str, Any]]:
    final = runtime.store.publish_run_artifacts(run_id, staging)
    return [
        {"name": name, "media_type": media, "size_bytes": (final / name).stat().st_size}
        for name, media in SUMMARY_ARTIFACTS.items()
        if (final / name).is_file()
    ]


# --- the webhook ------------------------------------------------------------------------


def webhook_payload(runtime: Runtime, run: ScheduleRun, schedule: Schedule) -> dict[str, Any]:
    """Return the JSON a webhook receives: the run, its links and each recording's verdicts."""
    base = runtime.settings.public_url.rstrip("/")
    run_url = f"{base}/api/v1/schedules/{schedule.id}/runs/{run.id}"
    return {
        "event": "schedule.run.finished",
        "schedule": {"id": schedule.id, "name": schedule.name},
        "run": {
            "id": run.id,
            "status": run.status,
            "trigger": run.trigger,
            "due_at": run.due_at.isoformat(),
            "finished_at": run.finished_at.isoformat() if run.finished_at else None,
            "note": run.note,
            "error": run.error,
            "url": run_url,
        },
        "links": {a["name"]: f"{run_url}/artifacts/{a['name']}" for a in run.artifacts or []},
        "recordings": [
            {
                "dataset": row.get("dataset"),
                "status": row.get("status"),
                "error": row.get("error"),
                "evaluation_url": (
                    f"{base}/api/v1/evaluations/{row['evaluation_id']}"
                    if row.get("evaluation_id")
                    else None
                ),
                "systems": row.get("summary") or [],
            }
            for row in run.rows or []
        ],
    }


def _notify(runtime: Runtime, run_id: str) -> None:
    """Post the run's summary to the schedule's webhook, retrying; record what happened."""
    try:
        with runtime.sessions() as session:
            run = session.get_one(ScheduleRun, run_id)
            schedule = session.get(Schedule, run.schedule_id)
        if schedule is None or not schedule.webhook_url or run.worker != runtime.worker_id:
            return
        body = json.dumps(webhook_payload(runtime, run, schedule)).encode("utf-8")
        record = _deliver(schedule.webhook_url, body)
        with runtime.sessions() as session:
            session.execute(
                update(ScheduleRun).where(ScheduleRun.id == run_id).values(webhook=record)
            )
            session.commit()
    except Exception:  # the run is done; a notification problem must not undo it
        logger.exception("Webhook of schedule run %s could not be handled", run_id)


def _deliver(url: str, body: bytes) -> dict[str, Any]:
    record: dict[str, Any] = {"url": url, "delivered": False, "attempts": []}
    for attempt in range(_WEBHOOK_ATTEMPTS):
        if attempt:
            time.sleep(2.0**attempt)
        entry: dict[str, Any] = {"at": utcnow().isoformat()}
        request = urllib.request.Request(  # noqa: S310  (http/https checked at creation)
            url,
            data=body,
            headers={"Content-Type": "application/json", "User-Agent": "loceval-webhook"},
            method="POST",
        )
        try:
            with urllib.request.urlopen(request, timeout=_WEBHOOK_TIMEOUT_S) as response:  # noqa: S310
                entry["status"] = response.status
        except urllib.error.HTTPError as err:
            entry["status"] = err.code
            entry["error"] = f"HTTP {err.code} {err.reason}"
        except (urllib.error.URLError, OSError, TimeoutError) as err:
            entry["error"] = str(getattr(err, "reason", err))
        record["attempts"].append(entry)
        if 200 <= int(entry.get("status", 0)) < 300:
            record["delivered"] = True
            break
    if not record["delivered"]:
        logger.warning("Webhook %s not delivered after %d attempts", url, _WEBHOOK_ATTEMPTS)
    return record
