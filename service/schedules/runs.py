"""What one schedule run does: evaluate the selected recordings, render the summary, notify.

A run is a tracked job (:func:`service.jobs.tracking.tracked_job`) of the kind ``run``. It
evaluates every selected recording with the schedule's template (as evaluation jobs, listed
with the others, run in this thread), renders one summary report and, if the schedule has a
webhook, queues its delivery: a queue task of its own, retried by the queue
(:func:`service.jobs.queue.create_runtime` gives it ``retries`` and ``retry_delay``), so no
consumer thread sleeps between attempts. Every attempt is recorded with the run.
"""

from __future__ import annotations

import datetime as dt
import http.client
import json
import logging
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final, TypeVar

import numpy as np
from sqlalchemy import select, update

from loceval.errors import InputError, LocevalError
from loceval.readers import SourceSpec, TrajectoryFormat, read_trajectory
from service.db import Dataset, Evaluation, JobStatus, Schedule, ScheduleRun, utcnow
from service.errors import ServiceUnavailableError, problem_for
from service.jobs.evaluations import create_evaluation
from service.jobs.kinds import EVALUATION, RUN
from service.jobs.kinds import WEBHOOK as WEBHOOK_TASK
from service.jobs.tracking import ProgressWriter, tracked_job
from service.runtime import Runtime
from service.schedules.resource import SUMMARY_ARTIFACTS, describe_selection, select_datasets
from service.schedules.summaries import summary_files
from service.schemas.evaluations import EstimateRef, EvaluationCreate, SourceRef
from service.schemas.schedules import (
    EvaluationTemplate,
    EvoResultRef,
    Produce,
    Selection,
    TemplateSource,
)
from service.uploads.evo_results import is_evo_result, read_evo_dataset
from service.webhooks import (
    AllowList,
    WebhookRefusedError,
    WebhookUnresolvedError,
    check_webhook_url,
    post,
    signature_headers,
)

__all__ = [
    "WEBHOOK",
    "WEBHOOK_ATTEMPTS",
    "WebhookNotDeliveredError",
    "deliver_webhook",
    "execute_schedule_run",
    "recording_start",
    "webhook_payload",
]

logger = logging.getLogger(__name__)

WEBHOOK: Final = WEBHOOK_TASK.name
"""The queue task that delivers a run's webhook (one attempt per execution)."""
WEBHOOK_ATTEMPTS: Final = WEBHOOK_TASK.attempts
"""How often a webhook is posted before the run records it as undelivered."""
_WEBHOOK_TIMEOUT_S: Final = 10.0
_EARLIEST_RECORDING: Final = dt.datetime(2000, 1, 1, tzinfo=dt.UTC)
"""Stamps before this are not dates (seconds since a device's start, as TUM and KITTI)."""
_NS: Final = 1_000_000_000


class WebhookNotDeliveredError(Exception):
    """A webhook attempt failed; raised inside the queue task so that the queue retries it."""


_Ref = TypeVar("_Ref", bound=SourceRef)
"""A reference or an estimate of a run's request."""


def execute_schedule_run(runtime: Runtime, run_id: str) -> None:
    """Evaluate the selected recordings, render the summary and queue the webhook."""
    with tracked_job(runtime, RUN, run_id, stage="selecting recordings") as job:
        if job is None:
            return
        run, schedule, datasets = _load(runtime, run_id)
        selection = Selection.model_validate(schedule.selection)
        picked = select_datasets(datasets, selection.model_dump(), as_of=run.due_at)
        entries = _with_named_evo_results(picked, datasets, selection)
        rows, summary_runs = _evaluate_all(runtime, run, schedule, entries, job.progress)
        staging = job.staging_dir()
        job.progress("writing the summary report", 0.85)
        _render(run, schedule, summary_runs, staging, runtime.settings.templates_dir)
        final = job.publish(staging)
        job.succeed(
            rows=rows,
            artifacts=[
                {"name": name, "media_type": media, "size_bytes": (final / name).stat().st_size}
                for name, media in SUMMARY_ARTIFACTS.items()
                if (final / name).is_file()
            ],
        )
    if job.finished_here:
        with runtime.sessions() as session:
            webhook_url = session.scalar(
                select(Schedule.webhook_url).where(Schedule.id == ScheduleRun.schedule_id)
                .where(ScheduleRun.id == run_id)
            )  # fmt: skip
        if webhook_url:
            try:
                runtime.enqueue(WEBHOOK, run_id)
            except ServiceUnavailableError:  # the run is done; only its notification is lost
                logger.warning("The webhook of run %s could not be queued", run_id, exc_info=True)


def _load(runtime: Runtime, run_id: str) -> tuple[ScheduleRun, Schedule, Sequence[Dataset]]:
    with runtime.sessions() as session:
        run = session.get_one(ScheduleRun, run_id)
        schedule = session.get(Schedule, run.schedule_id)
        if schedule is None:
            msg = "The schedule was deleted before its run started."
            raise InputError(msg)
        datasets = session.scalars(select(Dataset).where(Dataset.project_id == run.project_id))
        return run, schedule, datasets.all()


_Entry = tuple[Dataset | str, EvoResultRef | None]
"""A run's entry: a picked dataset (or the id of a named one that is gone) and its naming."""


def _with_named_evo_results(
    picked: Sequence[Dataset], datasets: Sequence[Dataset], selection: Selection
) -> list[_Entry]:
    """Return the picked datasets, then the evo result zips the selection names by id.

    A named zip the conditions picked too stays in its place with the given name; a named
    id no longer in the project stays as its id, so the run reports it as failed.
    """
    named = {ref.dataset_id: ref for ref in selection.evo_results}
    by_id = {d.id: d for d in datasets}
    entries: list[_Entry] = [(d, named.get(d.id)) for d in picked]
    seen = {d.id for d in picked}
    for dataset_id, ref in named.items():
        if dataset_id not in seen:
            entries.append((by_id.get(dataset_id, dataset_id), ref))
    return entries


def _evo_entry(runtime: Runtime, run: ScheduleRun, entry: _Entry) -> tuple[dict[str, Any], Any]:
    """Return the row and summary run of an evo result zip: its figures, marked as evo's."""
    from exporters.summary import SummaryRun  # noqa: PLC0415  (heavy, see _evaluate_all)
    from exporters.summary.evo import evo_summary_run  # noqa: PLC0415

    dataset, ref = entry
    if isinstance(dataset, str):
        reason = (
            f"The evo result {dataset!r} named in selection.evo_results is no longer in the "
            "project; upload it again and name its new id, or remove it from the schedule."
        )
        row = {"dataset_id": dataset, "dataset": dataset, "source": "evo"}
        failed = SummaryRun(
            dataset=dataset, recorded_at=run.due_at, status="failed", error=reason, source="evo"
        )
        return {**row, "status": "failed", "error": reason, "evaluation_id": None}, failed
    row = {"dataset_id": dataset.id, "dataset": dataset.name, "source": "evo"}
    try:
        result = read_evo_dataset(runtime, dataset)
    except LocevalError as err:
        reason = problem_for(err, private=runtime.private_roots)["detail"]
        failed_run = _failed_run(dataset, reason)
        return {**row, "status": "failed", "error": reason, "evaluation_id": None}, failed_run
    first_s = result.first_stamp_s
    recorded_at, is_upload = recording_start(
        {} if first_s is None else {"start_s": first_s}, dataset.created_at
    )
    summary_run = evo_summary_run(
        result,
        dataset=dataset.name,
        recorded_at=recorded_at,
        recorded_at_is_upload=is_upload,
        name=None if ref is None else ref.name,
    )
    systems = [
        {
            "name": name,
            "ate_rmse_m": figures.ate_rmse_m,
            "rpe_rmse_m": figures.rpe_rmse_m,
            "matched": figures.matched,
            "verdict": None,
        }
        for name, figures in summary_run.systems.items()
    ]
    return {
        **row,
        "status": "succeeded",
        "error": None,
        "evaluation_id": None,
        "summary": systems,
        "note": summary_run.source_note,
    }, summary_run


def _evaluate_all(
    runtime: Runtime,
    run: ScheduleRun,
    schedule: Schedule,
    entries: Sequence[_Entry],
    progress: ProgressWriter,
) -> tuple[list[dict[str, Any]], list[Any]]:
    """Run the template on every picked recording; failures become rows with the reason.

    An evo result zip is not evaluated: its row and summary run hold evo's figures.
    """
    # exporters.summary draws with matplotlib: imported when a run renders, not at start-up.
    from exporters.summary import SummaryRun  # noqa: PLC0415

    template = EvaluationTemplate.model_validate(schedule.template)
    per_run = Produce.model_validate(schedule.produce).per_run_artifacts
    rows: list[dict[str, Any]] = []
    summary_runs = []
    for k, entry in enumerate(entries):
        dataset = entry[0]
        fraction = 0.8 * k / max(len(entries), 1)
        if isinstance(dataset, str) or is_evo_result(dataset):
            name = dataset if isinstance(dataset, str) else dataset.name
            progress(f"reading the evo result {name}", fraction)
            evo_row, evo_run = _evo_entry(runtime, run, entry)
            rows.append(evo_row)
            summary_runs.append(evo_run)
            continue
        progress(f"evaluating {dataset.name}", fraction)
        row: dict[str, Any] = {"dataset_id": dataset.id, "dataset": dataset.name}
        options = template.options
        if not per_run:
            options = options.model_copy(update={"formats": ["result.json"]})
        body = EvaluationCreate(
            reference=_source_ref(template.reference, dataset, SourceRef),
            estimates=[_source_ref(e, dataset, EstimateRef) for e in template.estimates],
            options=options,
        )
        try:
            evaluation = create_evaluation(runtime, run.project_id, body, enqueue=False)
        except LocevalError as err:
            reason = problem_for(err, private=runtime.private_roots)["detail"]
            rows.append({**row, "status": "failed", "error": reason, "evaluation_id": None})
            summary_runs.append(_failed_run(dataset, reason))
            continue
        runtime.run_inline(EVALUATION, evaluation.id)
        with runtime.sessions() as session:
            done = session.get_one(Evaluation, evaluation.id)
        row["evaluation_id"] = done.id
        if done.status != JobStatus.SUCCEEDED or done.result is None:
            reason = (done.error or {}).get("detail", "The evaluation did not finish.")
            rows.append({**row, "status": "failed", "error": reason})
            summary_runs.append(_failed_run(dataset, reason, done.id))
            continue
        rows.append({**row, "status": "succeeded", "error": None, "summary": done.summary})
        recorded_at, is_upload = recording_start(dataset.inspection, dataset.created_at)
        reference_xyz, reference_t_s = _reference_path(runtime, dataset, template)
        summary_runs.append(
            SummaryRun.from_result(
                done.result,
                dataset=dataset.name,
                recorded_at=recorded_at,
                recorded_at_is_upload=is_upload,
                evaluation_id=done.id,
                reference_xyz=reference_xyz,
                reference_t_s=reference_t_s,
            )
        )
    return rows, summary_runs


def _source_ref(entry: TemplateSource, recording: Dataset, kind: type[_Ref]) -> _Ref:
    """Return the template's source in a recording, or in its fixed dataset (a survey)."""
    return kind(
        dataset_id=entry.dataset_id or recording.id, selector=entry.selector, name=entry.name
    )


def recording_start(
    inspection: Mapping[str, Any], uploaded_at: dt.datetime
) -> tuple[dt.datetime, bool]:
    """Return when a recording started, from its stamps, and whether that is the upload time.

    The start is the inspection's first stamp: a bag's ``start_ns``, a single trajectory's
    ``start_s``, else the earliest ``first_stamp_ns`` of its sources. Stamps that are not
    dates (before 2000, as seconds since a device started; or more than a day after the
    upload) give the upload time instead, so a backlog uploaded in one go keeps its order.

    Args:
        inspection: the dataset's stored inspection (:meth:`Inspection.to_dict`).
        uploaded_at: the dataset's upload time, aware.

    Returns:
        ``(start, is_upload)``: the start in UTC, and True when it is the upload time.
    """
    uploaded = uploaded_at if uploaded_at.tzinfo else uploaded_at.replace(tzinfo=dt.UTC)
    start_ns: float | None = None
    if isinstance(inspection.get("start_ns"), int):
        start_ns = float(inspection["start_ns"])
    elif isinstance(inspection.get("start_s"), int | float):
        start_ns = float(inspection["start_s"]) * _NS
    else:
        firsts = [
            float(s["first_stamp_ns"])
            for s in inspection.get("sources", [])
            if isinstance(s, Mapping) and isinstance(s.get("first_stamp_ns"), int)
        ]
        start_ns = min(firsts) if firsts else None
    if start_ns is not None and np.isfinite(start_ns):
        start = dt.datetime.fromtimestamp(start_ns / _NS, dt.UTC)
        if _EARLIEST_RECORDING <= start <= uploaded + dt.timedelta(days=1):
            return start, False
    return uploaded.astimezone(dt.UTC), True


def _failed_run(dataset: Dataset, reason: str, evaluation_id: str | None = None) -> Any:  # noqa: ANN401
    from exporters.summary import SummaryRun  # noqa: PLC0415  (heavy, see _evaluate_all)

    recorded_at, is_upload = recording_start(dataset.inspection, dataset.created_at)
    return SummaryRun(
        dataset=dataset.name,
        recorded_at=recorded_at,
        recorded_at_is_upload=is_upload,
        status="failed",
        error=reason,
        evaluation_id=evaluation_id,
    )


def _reference_path(
    runtime: Runtime, dataset: Dataset, template: EvaluationTemplate
) -> tuple[
    np.ndarray[Any, np.dtype[np.float64]] | None, np.ndarray[Any, np.dtype[np.float64]] | None
]:
    """Re-read the run's reference path and its times, seconds (None, None if unreadable)."""
    if template.reference.dataset_id is not None:
        return None, None  # a fixed reference (control points): the same in every run
    fmt = dataset.inspection.get("format")
    try:
        spec = SourceSpec(
            TrajectoryFormat(str(fmt)),
            runtime.store.local_path(
                dataset.storage_path, filename=dataset.filename, sha256=dataset.sha256
            ),
            template.reference.selector,
        )
        found = read_trajectory(spec, stamp=template.options.stamp)
    except (LocevalError, ValueError):
        return None, None
    return found.positions_xyz, found.stamps_ns / 1e9


def _render(
    run: ScheduleRun,
    schedule: Schedule,
    summary_runs: Sequence[Any],
    staging: Path,
    templates_dir: Path,
) -> None:
    files = summary_files(
        EvaluationTemplate.model_validate(schedule.template),
        summary_runs,
        Produce.model_validate(schedule.produce).summary_formats,
        title=schedule.name,
        selection=describe_selection(schedule.selection, as_of=run.due_at),
        templates_dir=templates_dir,
        generated_at=utcnow(),
        notes=[run.note] if run.note else [],
        schedule_id=schedule.id,
        run_id=run.id,
    )
    staging.mkdir(parents=True, exist_ok=True)
    for name, data in files.items():
        (staging / name).write_bytes(data)


# --- the webhook ------------------------------------------------------------------------


def webhook_payload(runtime: Runtime, run: ScheduleRun, schedule: Schedule) -> dict[str, Any]:
    """Return the JSON a webhook receives: the run, its links and each recording's verdicts."""
    base = runtime.settings.resolved_public_url.rstrip("/")
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
                "source": row.get("source", "loceval"),
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


def deliver_webhook(runtime: Runtime, run_id: str, *, attempt: int) -> None:
    """Post a finished run's summary to its schedule's webhook once and record the attempt.

    The URL is checked again first (:func:`service.webhooks.check_webhook_url`: the
    name may resolve elsewhere now, or the allow-list changed); a refused target is recorded with
    ``"refused": true`` and not retried, and neither is a redirect (3xx), which is never
    followed. The body is signed with the schedule's secret (``X-Loceval-Signature``).

    Raises:
        WebhookNotDeliveredError: the attempt failed and the queue has attempts left (the
            queue task retries on it); the last failed attempt is recorded and logged only.
    """
    with runtime.sessions() as session:
        run = session.get_one(ScheduleRun, run_id)
        schedule = session.get(Schedule, run.schedule_id)
    if schedule is None or not schedule.webhook_url:
        return
    url = schedule.webhook_url
    body = json.dumps(webhook_payload(runtime, run, schedule)).encode("utf-8")
    entry, final = _attempt(runtime, url, body, schedule.webhook_secret)
    delivered = 200 <= int(entry.get("status", 0)) < 300
    record: dict[str, Any] = dict(run.webhook or {}) if attempt > 1 else {}
    record = {
        "url": url,
        "delivered": delivered,
        "attempts": [*record.get("attempts", []), entry],
    }
    if entry.get("refused"):
        record["refused"] = True
    with runtime.sessions() as session:
        session.execute(update(ScheduleRun).where(ScheduleRun.id == run_id).values(webhook=record))
        session.commit()
    if delivered:
        return
    if final:
        logger.warning("Webhook of run %s not delivered, not retried: %s", run_id, entry["error"])
        return
    if attempt < WEBHOOK_ATTEMPTS:
        msg = f"Webhook {url} attempt {attempt} failed: {entry.get('error')}; the queue retries."
        raise WebhookNotDeliveredError(msg)
    logger.warning("Webhook %s not delivered after %d attempts", url, WEBHOOK_ATTEMPTS)


def _attempt(runtime: Runtime, url: str, body: bytes, secret: str) -> tuple[dict[str, Any], bool]:
    """Check the target and post once; return the attempt's record and whether it is final.

    Final (not retried): a refused target and a redirect. A host that does not resolve, a
    connection error and any other answer may be retried.
    """
    entry: dict[str, Any] = {"at": utcnow().isoformat()}
    started = time.monotonic()
    final = False
    try:
        target = check_webhook_url(url, AllowList.parse(runtime.settings.webhook_allow))
        headers = {
            "Content-Type": "application/json",
            "User-Agent": "loceval-webhook",
            **signature_headers(secret, body),
        }
        status, location = post(target, body, headers, timeout=_WEBHOOK_TIMEOUT_S)
    except WebhookUnresolvedError as err:
        entry["error"] = str(err)
    except WebhookRefusedError as err:
        entry.update(error=f"Refused: {err}", refused=True)
        final = True
    except (OSError, ValueError, http.client.HTTPException) as err:  # ValueError: InvalidURL
        entry["error"] = str(err) or type(err).__name__
    else:
        entry["status"] = status
        if 300 <= status < 400:
            entry["error"] = (
                f"HTTP {status} redirect{f' to {location}' if location else ''} not followed; "
                "give the final URL as webhook_url."
            )
            final = True
        elif not 200 <= status < 300:
            entry["error"] = f"HTTP {status} {http.client.responses.get(status, '')}".rstrip()
    logger.info(
        "webhook attempt",
        extra={
            "event": "webhook",
            "status": entry.get("status"),
            "duration_ms": round((time.monotonic() - started) * 1000, 1),
        },
    )
    return entry, final
