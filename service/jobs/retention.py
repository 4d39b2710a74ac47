"""Deleting evaluations: one on request, and every finished one past the retention period.

What goes and what stays:

- An evaluation is deleted with its row and its folder (artifacts, staging leftovers). Only
  a finished one (succeeded or failed) can be: a queued or running evaluation is refused
  (409) until it has finished, since its worker would otherwise write into a deleted job.
- A schedule run that evaluated it keeps its summary report and its per-recording figures
  (they are copies); its row for that recording gains ``"evaluation_deleted": true``, so the
  run says why its evaluation link answers 404.
- Datasets are never swept: they are the inputs, schedules select them by tag and date, and
  only their owner knows when one may go (``DELETE /datasets/{id}``).
- The hourly sweep (:func:`sweep`) deletes finished evaluations older than
  ``retention_days`` (by their finish time), then the orphans: artifact folders of
  evaluations and schedule runs that have no row (a crash between deleting a row and its
  folder), and uploads abandoned mid-transfer. Orphans younger than an hour are left alone,
  so a job or upload in progress is never touched. It logs one line with the counts.
"""

from __future__ import annotations

import datetime as dt
import logging
import re
import time
from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Final

from sqlalchemy import and_, delete, or_, select, update
from sqlalchemy.orm import Session

from service.blobs.base import EVALUATIONS, RUNS, Swept
from service.db import Dataset, Evaluation, JobStatus, ScheduleRun, get_owned, utcnow
from service.errors import ConflictError, NotFoundError
from service.jobs.kinds import EVALUATION
from service.logs import log_transition
from service.runtime import JobModel, Runtime

__all__ = [
    "FINISHED_STATUSES",
    "SweepCounts",
    "delete_evaluation",
    "sweep",
    "sweep_leftovers",
    "sweep_orphans",
]

logger = logging.getLogger(__name__)

FINISHED_STATUSES: Final = (JobStatus.SUCCEEDED, JobStatus.FAILED)
"""The states of an evaluation that may be deleted."""

_BATCH: Final = 200
_ORPHAN_GRACE_S: Final = 3600.0
_ID: Final = re.compile(r"[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}")


@dataclass(frozen=True, slots=True)
class SweepCounts:
    """What one sweep removed.

    Attributes:
        evaluations: finished evaluations past the retention period (rows and folders).
        orphans: job folders without a row (evaluations and schedule runs).
        partial_uploads: uploads abandoned mid-transfer.
        unrecorded_datasets: dataset folders whose upload died before its row was recorded.
    """

    evaluations: int
    orphans: int
    partial_uploads: int
    unrecorded_datasets: int = 0


def delete_evaluation(runtime: Runtime, project_id: str, evaluation_id: str) -> None:
    """Delete a finished evaluation of the project, with its artifacts.

    Raises:
        NotFoundError: no such evaluation in the project.
        ConflictError: the evaluation is queued or running.
    """
    evaluation = get_owned(runtime.sessions, Evaluation, evaluation_id, project_id)
    with runtime.sessions() as session:
        done = session.execute(
            delete(Evaluation).where(
                Evaluation.id == evaluation.id,
                Evaluation.project_id == project_id,
                Evaluation.status.in_(FINISHED_STATUSES),
            )
        )
        if not done.rowcount:  # type: ignore[attr-defined]
            session.rollback()
            current = session.get(Evaluation, evaluation.id)
            if current is None:  # deleted by a concurrent request or sweep
                msg = f"No evaluation {evaluation_id!r} in this project; it was just deleted."
                raise NotFoundError(msg)
            msg = (
                f"Evaluation {evaluation_id!r} is {current.status} and cannot be deleted "
                "until it has finished; poll GET /evaluations/{id} and delete it once it "
                "has succeeded or failed."
            )
            raise ConflictError(msg)
        _mark_deleted_in_runs(session, project_id, {evaluation.id})
        session.commit()
    runtime.store.remove_job(EVALUATIONS, evaluation.id)
    log_transition("deleted", EVALUATION, evaluation.id, project=project_id)


def _mark_deleted_in_runs(session: Session, project_id: str, deleted: set[str]) -> None:
    """Flag the rows of the project's schedule runs whose evaluation was deleted."""
    runs = session.execute(
        select(ScheduleRun.id, ScheduleRun.rows).where(ScheduleRun.project_id == project_id)
    ).all()
    for run_id, rows in runs:
        if not isinstance(rows, list) or not any(
            isinstance(r, dict) and r.get("evaluation_id") in deleted for r in rows
        ):
            continue
        marked: list[Any] = [
            {**r, "evaluation_deleted": True}
            if isinstance(r, dict) and r.get("evaluation_id") in deleted
            else r
            for r in rows
        ]
        session.execute(update(ScheduleRun).where(ScheduleRun.id == run_id).values(rows=marked))


def _expired_batch(runtime: Runtime, cutoff: dt.datetime) -> tuple[int, int]:
    """Delete up to one batch of finished evaluations that ended before ``cutoff``.

    Returns:
        How many were found and how many of them this call deleted (a sweep running in
        another worker at the same time may have taken some).
    """
    ended_before = or_(
        Evaluation.finished_at < cutoff,
        and_(Evaluation.finished_at.is_(None), Evaluation.created_at < cutoff),
    )
    with runtime.sessions() as session:
        rows = session.execute(
            select(Evaluation.id, Evaluation.project_id)
            .where(Evaluation.status.in_(FINISHED_STATUSES), ended_before)
            .limit(_BATCH)
        ).all()
        if not rows:
            return 0, 0
        ids = [str(job_id) for job_id, _ in rows]
        done = session.execute(
            delete(Evaluation).where(
                Evaluation.id.in_(ids), Evaluation.status.in_(FINISHED_STATUSES)
            )
        )
        by_project: dict[str, set[str]] = defaultdict(set)
        for job_id, project_id in rows:
            by_project[str(project_id)].add(str(job_id))
        for project_id, deleted in by_project.items():
            _mark_deleted_in_runs(session, project_id, deleted)
        session.commit()
    for job_id in ids:
        runtime.store.remove_job(EVALUATIONS, job_id)
    return len(ids), int(done.rowcount)  # type: ignore[attr-defined]


def sweep_leftovers(runtime: Runtime, *, startup: bool = False) -> Swept:
    """Remove what upload processes that are gone left: partial uploads, unrecorded datasets.

    Runs on every start, once a minute in the workers and in the hourly sweep; an owner
    still running (its lock held) keeps everything (:meth:`service.blobs.local.LocalBlobs.sweep`).
    """
    swept = runtime.store.sweep(lambda ids: _existing(runtime, Dataset, ids), startup=startup)
    if swept.partial_uploads or swept.datasets:
        logger.warning(
            "Removed %d partial uploads and %d unrecorded dataset folders left by processes "
            "that are gone",
            swept.partial_uploads,
            swept.datasets,
            extra={
                "event": "leftovers_swept",
                "partial_uploads": swept.partial_uploads,
                "datasets": swept.datasets,
            },
        )
    return swept


def _existing(runtime: Runtime, model: JobModel | type[Dataset], ids: Sequence[str]) -> set[str]:
    """Return which of ``ids`` have a row in ``model``'s table."""
    found: set[str] = set()
    with runtime.sessions() as session:
        for start in range(0, len(ids), _BATCH):
            chunk = ids[start : start + _BATCH]
            found.update(
                str(i) for i in session.scalars(select(model.id).where(model.id.in_(chunk)))
            )
    return found


def sweep_orphans(runtime: Runtime, *, grace_s: float = _ORPHAN_GRACE_S) -> int:
    """Delete job folders (evaluations, schedule runs) that have no row; return how many.

    Only folders named by a job id and untouched for ``grace_s`` seconds are considered, so
    a job being written is never removed. Datasets' folders are left alone: an upload is
    moved into place before its row is recorded, and a dataset is not re-creatable.
    """
    cutoff = time.time() - grace_s
    removed = 0
    folders: Iterable[tuple[str, JobModel]] = ((EVALUATIONS, Evaluation), (RUNS, ScheduleRun))
    for folder, model in folders:
        candidates = {
            job_id
            for job_id, written in runtime.store.job_ids(folder).items()
            if _ID.fullmatch(job_id) and written < cutoff
        }
        for job_id in sorted(candidates - _existing(runtime, model, sorted(candidates))):
            runtime.store.remove_job(folder, job_id)
            removed += 1
    return removed


def sweep(runtime: Runtime, *, now: dt.datetime | None = None) -> SweepCounts:
    """Delete what the retention setting lets go, and the orphans; log one line.

    Args:
        runtime: the process's runtime (``settings.retention_days``: 0 keeps evaluations).
        now: the current time (for tests; default: now).

    Returns:
        The counts of what was removed.
    """
    days = runtime.settings.retention_days
    expired = 0
    cutoff = None
    if days > 0:
        cutoff = (now or utcnow()) - dt.timedelta(days=days)
        while True:
            found, deleted = _expired_batch(runtime, cutoff)
            expired += deleted
            if found < _BATCH:
                break
    left = sweep_leftovers(runtime)
    counts = SweepCounts(
        evaluations=expired,
        orphans=sweep_orphans(runtime),
        partial_uploads=left.partial_uploads,
        unrecorded_datasets=left.datasets,
    )
    logger.info(
        "Retention sweep: %d evaluations %s, %d orphaned job folders, %d abandoned uploads removed",
        counts.evaluations,
        f"finished before {cutoff:%Y-%m-%d %H:%M} UTC" if cutoff else "(kept: no retention set)",
        counts.orphans,
        counts.partial_uploads,
        extra={
            "event": "retention_sweep",
            "evaluations": counts.evaluations,
            "orphans": counts.orphans,
            "partial_uploads": counts.partial_uploads,
            "retention_days": days,
        },
    )
    return counts
