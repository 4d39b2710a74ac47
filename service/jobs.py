"""Evaluation jobs on huey's queue: the runtime, the task, and recovery after crashes.

Job state lives in the database, not in the queue or in process memory: the queue carries
only evaluation ids. A worker claims a job with a conditional update (``queued -> running``),
so a job enqueued twice runs once; while it runs it beats a heartbeat. A job whose heartbeat
stops (the worker crashed or the service restarted) is found by :func:`recover`, on start and
once a minute, and is queued again (the work is idempotent: artifacts are rebuilt from the
inputs) or, after ``job_attempts`` starts, marked failed with the reason.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import os
import shutil
import socket
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from huey import Huey, MemoryHuey, RedisHuey, SqliteHuey, crontab
from huey.consumer import Consumer
from sqlalchemy import Engine, or_, select, update
from sqlalchemy.orm import Session, sessionmaker

from loceval.errors import InputError, LocevalError
from loceval.readers import SourceSpec, TrajectoryFormat
from service.db import (
    Dataset,
    Evaluation,
    EvaluationStatus,
    ScheduleRun,
    create_db_engine,
    make_session_factory,
    migrate,
    utcnow,
)
from service.errors import internal_problem, problem, problem_for
from service.options import (
    config_from_options,
    device_offset,
    export_from_options,
    offset_or_none,
)
from service.runner import Job, JobSource, file_provenance, run_job
from service.schemas import EvaluationOptions
from service.settings import Settings
from service.storage import BlobStore

__all__ = [
    "Heartbeat",
    "JobModel",
    "ProgressWriter",
    "Runtime",
    "claim",
    "create_runtime",
    "evaluation_summary",
    "execute_evaluation",
    "finish",
    "recover",
    "release",
]

logger = logging.getLogger(__name__)

_TASK_NAME: Final = "run_evaluation"
_RUN_TASK_NAME: Final = "run_schedule"
_PROGRESS_INTERVAL_S: Final = 0.5


@dataclass
class Runtime:
    """What a service or worker process shares: settings, database, blobs and the queue."""

    settings: Settings
    engine: Engine
    sessions: sessionmaker[Session]
    store: BlobStore
    huey: Huey
    worker_id: str
    enqueue_task: Callable[[str], object]
    enqueue_run_task: Callable[[str], object]

    def enqueue(self, evaluation_id: str) -> None:
        """Queue an evaluation (in immediate mode: run it now)."""
        self.enqueue_task(evaluation_id)

    def enqueue_schedule_run(self, run_id: str) -> None:
        """Queue a schedule run (in immediate mode: run it now)."""
        self.enqueue_run_task(run_id)

    def start_consumer(self, *, periodic: bool = True) -> Consumer:
        """Start queue consumer threads in this process (no signal handlers of its own)."""
        consumer = _EmbeddedConsumer(
            self.huey,
            workers=self.settings.workers,
            worker_type="thread",
            periodic=periodic,
            max_delay=2.0,
            check_worker_health=True,
            shutdown_timeout=10.0,
        )
        consumer.start()
        return consumer

    def stop_consumer(self, consumer: Consumer) -> None:
        """Stop the consumer (running jobs get 10 s) and queue again what did not finish."""
        consumer.stop(graceful=True)
        released = release(self)
        if released:
            logger.warning("Queued %d unfinished evaluations again for the next start", released)

    def close(self) -> None:
        """Release the database connections."""
        self.engine.dispose()


class _EmbeddedConsumer(Consumer):  # type: ignore[misc]
    """huey's consumer without its signal handlers: uvicorn owns the signals in ``serve``."""

    def _set_signal_handlers(self) -> None:
        """Leave the process's signal handlers alone."""


def _create_huey(settings: Settings) -> Huey:
    if settings.queue_url == "immediate":
        return MemoryHuey("loceval", immediate=True, results=False)
    if settings.queue_url.startswith(("redis://", "rediss://")):
        return RedisHuey("loceval", url=settings.queue_url, results=False)
    queue_db = (settings.data_dir / "queue.db").resolve()
    return SqliteHuey("loceval", filename=str(queue_db), results=False, timeout=30)


def create_runtime(settings: Settings, *, apply_migrations: bool = True) -> Runtime:
    """Open the database (migrated to the newest schema), the blob store and the queue."""
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    engine = create_db_engine(settings.resolved_database_url)
    if apply_migrations:
        migrate(engine)
    huey = _create_huey(settings)
    runtime_box: list[Runtime] = []

    @huey.task(name=_TASK_NAME)  # type: ignore[untyped-decorator]
    def run_evaluation(evaluation_id: str) -> None:
        execute_evaluation(runtime_box[0], evaluation_id)

    @huey.task(name=_RUN_TASK_NAME)  # type: ignore[untyped-decorator]
    def run_schedule(run_id: str) -> None:
        from service.schedules import execute_schedule_run  # noqa: PLC0415

        execute_schedule_run(runtime_box[0], run_id)

    @huey.periodic_task(crontab(minute="*"), name="every_minute")  # type: ignore[untyped-decorator]
    def every_minute() -> None:
        from service.schedules import tick  # noqa: PLC0415

        recover(runtime_box[0])
        tick(runtime_box[0])

    runtime = Runtime(
        settings=settings,
        engine=engine,
        sessions=make_session_factory(engine),
        store=BlobStore(settings.data_dir),
        huey=huey,
        worker_id=f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:6]}",
        enqueue_task=run_evaluation,
        enqueue_run_task=run_schedule,
    )
    runtime_box.append(runtime)
    return runtime


# --- the task --------------------------------------------------------------------------


def execute_evaluation(runtime: Runtime, evaluation_id: str) -> None:
    """Run one evaluation job to succeeded or failed; a no-op if someone else claimed it."""
    if not claim(runtime, Evaluation, evaluation_id):
        return
    heartbeat = Heartbeat(runtime, Evaluation, evaluation_id)
    heartbeat.start()
    staging: Path | None = None
    try:
        with runtime.sessions() as session:
            evaluation = session.get_one(Evaluation, evaluation_id)
            job = _job_for(session, runtime, evaluation)
        runtime.store.clear_evaluation(evaluation_id)
        staging = runtime.store.staging_dir(evaluation_id)
        progress = ProgressWriter(runtime, Evaluation, evaluation_id)
        run_job(job, staging, progress)
        artifacts = _publish(runtime, evaluation_id, staging)
        staging = None
        document = json.loads(
            (runtime.store.artifacts_dir(evaluation_id) / "result.json").read_text()
        )
        finish(
            runtime,
            Evaluation,
            evaluation_id,
            status=EvaluationStatus.SUCCEEDED,
            result=document,
            summary=evaluation_summary(document),
            artifacts=artifacts,
        )
    except LocevalError as err:
        body = problem_for(err)
        body["detail"] = runtime.store.scrub(body["detail"])
        finish(runtime, Evaluation, evaluation_id, status=EvaluationStatus.FAILED, error=body)
    except Exception:
        error_id = uuid.uuid4().hex[:12]
        logger.exception("Evaluation %s failed with a bug (error_id=%s)", evaluation_id, error_id)
        finish(
            runtime,
            Evaluation,
            evaluation_id,
            status=EvaluationStatus.FAILED,
            error=internal_problem(error_id),
        )
    finally:
        heartbeat.stop()
        if staging is not None:
            shutil.rmtree(staging, ignore_errors=True)


JobModel = type[Evaluation] | type[ScheduleRun]
"""A table of queued jobs (both have the :class:`~service.db.JobState` columns)."""


def claim(runtime: Runtime, model: JobModel, job_id: str, *, stage: str = "starting") -> bool:
    """Move a queued job to running for this worker; False if someone else has it."""
    now = utcnow()
    with runtime.sessions() as session:
        claimed = session.execute(
            update(model)
            .where(model.id == job_id, model.status == EvaluationStatus.QUEUED)
            .values(
                status=EvaluationStatus.RUNNING,
                attempts=model.attempts + 1,
                worker=runtime.worker_id,
                heartbeat_at=now,
                started_at=now,
                stage=stage,
                fraction=0.0,
            )
        )
        session.commit()
        return bool(claimed.rowcount)  # type: ignore[attr-defined]


def finish(
    runtime: Runtime,
    model: JobModel,
    job_id: str,
    *,
    status: str,
    **values: Any,  # noqa: ANN401
) -> None:
    """Record a job's end, if this worker still holds it (else a recovered copy owns it)."""
    succeeded = status == EvaluationStatus.SUCCEEDED
    with runtime.sessions() as session:
        session.execute(
            update(model)
            .where(model.id == job_id, model.worker == runtime.worker_id)
            .values(
                status=status,
                # A failed job keeps the stage it failed in ("reading est", "writing report.pdf").
                stage="done" if succeeded else model.stage,
                fraction=1.0 if succeeded else model.fraction,
                finished_at=utcnow(),
                heartbeat_at=None,
                **values,
            )
        )
        session.commit()


def _publish(runtime: Runtime, evaluation_id: str, staging: Path) -> list[dict[str, Any]]:
    from exporters import ARTIFACTS  # noqa: PLC0415

    final = runtime.store.publish_artifacts(evaluation_id, staging)
    return [
        {
            "name": name,
            "media_type": spec.media_type,
            "size_bytes": (final / name).stat().st_size,
        }
        for name, spec in ARTIFACTS.items()
        if (final / name).is_file()
    ]


def evaluation_summary(document: dict[str, Any]) -> list[dict[str, Any]]:
    """Return the headline figures per estimate from a result document."""
    rows = []
    for estimate in document.get("estimates", []):
        verdict = estimate.get("verdict")
        rows.append(
            {
                "name": estimate.get("name"),
                "ate_rmse_m": (estimate.get("ate") or {}).get("translation_m", {}).get("rmse"),
                "rpe_rmse_m": (estimate.get("rpe") or {}).get("translation_m", {}).get("rmse"),
                "matched": estimate.get("matched"),
                "verdict": None if not verdict else ("pass" if verdict.get("passed") else "fail"),
            }
        )
    return rows


class ProgressWriter:
    """Store a job's progress, at most twice a second (and whenever the stage changes)."""

    def __init__(self, runtime: Runtime, model: JobModel, job_id: str) -> None:
        """Write to the row ``job_id`` of ``model``."""
        self.runtime = runtime
        self.model = model
        self.job_id = job_id
        self._last = 0.0
        self._stage = ""

    def __call__(self, stage: str, fraction: float) -> None:
        """Record the stage and the fraction done."""
        now = time.monotonic()
        if stage == self._stage and now - self._last < _PROGRESS_INTERVAL_S:
            return
        self._last, self._stage = now, stage
        with self.runtime.sessions() as session:
            session.execute(
                update(self.model)
                .where(self.model.id == self.job_id)
                .values(stage=stage[:200], fraction=min(max(fraction, 0.0), 1.0))
            )
            session.commit()


class Heartbeat:
    """A thread that stamps a job's ``heartbeat_at`` while it runs."""

    def __init__(self, runtime: Runtime, model: JobModel, job_id: str) -> None:
        """Beat for the row ``job_id`` of ``model`` (start it with :meth:`start`)."""
        self.runtime = runtime
        self.model = model
        self.job_id = job_id
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"heartbeat-{job_id[:8]}")
        self._thread.daemon = True

    def start(self) -> None:
        """Start beating."""
        self._thread.start()

    def stop(self) -> None:
        """Stop beating (waits up to 5 s for the thread)."""
        self._stop.set()
        self._thread.join(timeout=5)

    def _run(self) -> None:
        interval = max(self.runtime.settings.job_lease_s / 4, 0.2)
        model = self.model
        while not self._stop.wait(interval):
            try:
                with self.runtime.sessions() as session:
                    session.execute(
                        update(model)
                        .where(model.id == self.job_id, model.status == EvaluationStatus.RUNNING)
                        .values(heartbeat_at=utcnow())
                    )
                    session.commit()
            except Exception:  # a lost beat is retried; the job itself goes on
                logger.warning("Heartbeat of %s failed", self.job_id, exc_info=True)


# --- building the job ------------------------------------------------------------------


def _job_for(session: Session, runtime: Runtime, evaluation: Evaluation) -> Job:
    request = evaluation.request
    options = EvaluationOptions.model_validate(request.get("options", {}))
    reference = _source(session, runtime, evaluation.project_id, request["reference"], "reference")
    estimates = [
        _source(session, runtime, evaluation.project_id, e, "estimate")
        for e in request["estimates"]
    ]
    offset = offset_or_none(options.offset)
    device = options.device
    if device:
        dataset = _dataset(session, evaluation.project_id, device.dataset_id)
        offset = device_offset(
            runtime.store.path(dataset.storage_path),
            from_link=device.from_link,
            to_link=device.to_link,
            offset=options.offset,
        )
    config = config_from_options(options, reference_offset=offset)
    export = export_from_options(options, evaluation_id=evaluation.id)
    return Job(
        reference=reference,
        estimates=estimates,
        config=config,
        stamp=options.stamp,
        export=export,
        formats=options.formats,
    )


def _dataset(session: Session, project_id: str, dataset_id: str) -> Dataset:
    dataset = session.get(Dataset, dataset_id)
    if dataset is None or dataset.project_id != project_id:
        msg = (
            f"Dataset {dataset_id!r} was deleted after the evaluation was queued; upload it again."
        )
        raise InputError(msg)
    return dataset


def _source(
    session: Session, runtime: Runtime, project_id: str, ref: dict[str, Any], role: str
) -> JobSource:
    dataset = _dataset(session, project_id, ref["dataset_id"])
    fmt = dataset.inspection.get("format")
    if fmt not in {f.value for f in TrajectoryFormat}:
        msg = f"Dataset {dataset.name!r} is a {dataset.kind} file, not a trajectory recording."
        raise InputError(msg)
    spec = SourceSpec(
        TrajectoryFormat(fmt), runtime.store.path(dataset.storage_path), ref.get("selector")
    )
    provenance = file_provenance(role, spec, sha256=dataset.sha256)
    provenance.update(path=dataset.filename, dataset_id=dataset.id)
    name = ref.get("name") or ref.get("selector") or Path(dataset.filename).stem
    return JobSource(spec, str(name), provenance, display_path=dataset.filename)


# --- recovery --------------------------------------------------------------------------


_INTERRUPTED: Final[dict[JobModel, tuple[str, str, str]]] = {
    Evaluation: (
        "evaluation.interrupted",
        "JobInterrupted",
        (
            "The evaluation was interrupted {n} times (its worker stopped: a crash, a restart "
            "or running out of memory) and is not retried again; check the server log, and "
            "give the server more memory for very large recordings."
        ),
    ),
    ScheduleRun: (
        "run.interrupted",
        "RunInterrupted",
        (
            "The run was interrupted {n} times (its worker stopped) and is not retried again; "
            "check the server log."
        ),
    ),
}


def _enqueue(runtime: Runtime, model: JobModel, job_id: str) -> None:
    if model is Evaluation:
        runtime.enqueue(job_id)
    else:
        runtime.enqueue_schedule_run(job_id)


def recover(runtime: Runtime, *, now: dt.datetime | None = None) -> list[str]:
    """Re-queue or fail jobs whose worker stopped; return the ids that were re-queued.

    A running job (evaluation or schedule run) whose heartbeat is older than the lease was
    abandoned: it is queued again unless it has been started ``job_attempts`` times, then
    it fails with the reason. A queued job that the queue no longer holds (a Redis without
    persistence restarted) is enqueued again; the claim makes a duplicate harmless.
    """
    now = now or utcnow()
    stale = {model: _requeue_stale(runtime, model, now) for model in _INTERRUPTED}
    lost: dict[JobModel, list[str]] = {model: [] for model in _INTERRUPTED}
    if not runtime.huey.immediate:
        queued = {model: _queued_before(runtime, model, now) for model in _INTERRUPTED}
        if any(queued.values()):
            pending = {str(t.args[0]) for t in runtime.huey.pending() if t.args}
            for model, ids in queued.items():
                lost[model] = sorted(ids - pending - set(stale[model]))
    for model in _INTERRUPTED:
        for job_id in stale[model] + lost[model]:
            logger.warning("%s %s queued again after an interruption", model.__name__, job_id)
            _enqueue(runtime, model, job_id)
    return stale[Evaluation] + lost[Evaluation]


def _requeue_stale(runtime: Runtime, model: JobModel, now: dt.datetime) -> list[str]:
    """Mark abandoned running jobs queued (or failed at the attempt limit); return the queued."""
    cutoff = now - dt.timedelta(seconds=runtime.settings.job_lease_s)
    code, title, detail = _INTERRUPTED[model]
    requeued: list[str] = []
    with runtime.sessions() as session:
        stale = session.execute(
            select(model.id, model.attempts, model.heartbeat_at).where(
                model.status == EvaluationStatus.RUNNING,
                or_(model.heartbeat_at.is_(None), model.heartbeat_at < cutoff),
            )
        ).all()
        for job_id, attempts, beat in stale:
            if attempts >= runtime.settings.job_attempts:
                values: dict[str, Any] = {
                    "status": EvaluationStatus.FAILED,
                    "stage": "failed",
                    "finished_at": now,
                    "error": problem(500, code, title, detail.format(n=attempts)),
                }
            else:
                values = {
                    "status": EvaluationStatus.QUEUED,
                    "stage": f"queued again after an interruption (attempt {attempts})",
                    "fraction": 0.0,
                }
            done = session.execute(
                update(model)
                .where(
                    model.id == job_id,
                    model.status == EvaluationStatus.RUNNING,
                    model.heartbeat_at == beat,
                )
                .values(**values)
            )
            if done.rowcount and values["status"] == EvaluationStatus.QUEUED:  # type: ignore[attr-defined]
                requeued.append(job_id)
        session.commit()
    return requeued


def _queued_before(runtime: Runtime, model: JobModel, now: dt.datetime) -> set[str]:
    """Return the jobs queued for more than a minute (candidates for a lost queue entry)."""
    with runtime.sessions() as session:
        return set(
            session.scalars(
                select(model.id).where(
                    model.status == EvaluationStatus.QUEUED,
                    model.created_at < now - dt.timedelta(seconds=60),
                )
            ).all()
        )


def release(runtime: Runtime) -> int:
    """Queue again the jobs this process was running when it stopped; return how many.

    Their threads are abandoned (daemon threads end with the process); whatever they still
    write is ignored, because a finished job is recorded only by the worker that holds it.
    """
    released = 0
    for model in _INTERRUPTED:
        with runtime.sessions() as session:
            ids = session.scalars(
                select(model.id).where(
                    model.status == EvaluationStatus.RUNNING, model.worker == runtime.worker_id
                )
            ).all()
            session.execute(
                update(model)
                .where(
                    model.id.in_(ids),
                    model.status == EvaluationStatus.RUNNING,
                    model.worker == runtime.worker_id,
                )
                .values(
                    status=EvaluationStatus.QUEUED,
                    worker=None,
                    heartbeat_at=None,
                    stage="queued again: the service stopped while it ran",
                    fraction=0.0,
                )
            )
            session.commit()
        for job_id in ids:
            _enqueue(runtime, model, job_id)
        released += len(ids)
    return released
