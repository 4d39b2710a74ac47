"""The life of a tracked job, the same for every job kind: claim, beat, finish, recover.

Job state lives in the database, not in the queue or in process memory: the queue carries
only job ids. A worker claims a job with a conditional update (``queued -> running``), so a
job enqueued twice runs once; while it runs it beats a heartbeat. A job whose heartbeat stops
(the worker crashed or the service restarted) is found by :func:`recover`, on start and every
few seconds (:mod:`service.jobs.watchdog`), and is queued again (the work is idempotent: artifacts
are rebuilt from the inputs) or, after ``job_attempts`` starts, marked failed with the reason.

The database may be away for a moment (a restart, a failover). Nothing is lost then: a claim,
a progress write, a heartbeat or the final write that fails with an outage error is retried with
backoff (:func:`persist`); a job that still cannot claim, or whose own reads fail, is put back
(``queued``, the attempt not counted) and :class:`JobDeferred` tells the queue task to queue
it again later. A job that cannot read its inputs from the object store, or write its
artifacts there, once the client's own retries are spent is put back the same way. An
outage is never recorded as the job's failure, nor logged as a bug.

:func:`tracked_job` is the one sequence every executor runs inside; each transition (queued,
started, succeeded, failed, requeued) is one log line with the kind, job id, project,
attempt and duration.
"""

from __future__ import annotations

import datetime as dt
import logging
import shutil
import threading
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from sqlalchemy import or_, select, update

from loceval.errors import LocevalError
from service.adapters import BACKOFF_MAX_S, DATABASE_ERRORS, persist
from service.db import JobStatus, utcnow
from service.errors import StoreUnavailableError, internal_problem, problem, problem_for
from service.logs import log_context, log_transition
from service.runtime import JobKind, JobModel, Runtime

__all__ = [
    "CLAIM_PATIENCE_S",
    "FINISH_PATIENCE_S",
    "Heartbeat",
    "JobDeferred",
    "ProgressWriter",
    "TrackedJob",
    "beat_interval",
    "claim",
    "finish",
    "recover",
    "release",
    "tracked_job",
]

logger = logging.getLogger(__name__)

_PROGRESS_INTERVAL_S: Final = 0.5
CLAIM_PATIENCE_S: Final = 30.0
"""How long a worker thread retries a claim before it puts the message back in the queue
(with a delay) and takes the next one: a long outage does not hold a thread for ever."""
FINISH_PATIENCE_S: Final = 300.0
"""How long the end of a finished job is retried (its artifacts are published; giving up
means the lease runs out and the job runs again)."""
_BEAT_MAX_S: Final = 2.0
_BEAT_MIN_S: Final = 0.2


class JobDeferred(Exception):  # noqa: N818  (not an error of the job: it is put off)
    """The job could not be claimed or run because the database was away; queue it again.

    Not a :class:`LocevalError`: the job has not failed. The queue task turns it into a
    retry of the message after a delay (:func:`service.jobs.queue.create_runtime`).
    """


_OUTAGES: Final[tuple[type[Exception], ...]] = (
    *DATABASE_ERRORS,
    JobDeferred,
    StoreUnavailableError,
)
"""What ends a job's run without ending the job: it is put back and queued again."""


def _unreachable(err: Exception) -> str:
    """Name what an outage made unreachable: the object store or the database."""
    return "the object store" if isinstance(err, StoreUnavailableError) else "the database"


def beat_interval(lease_s: float) -> float:
    """Return the heartbeat period (also the re-queue check's): a fifth of the lease, <= 2 s.

    With the default lease of 10 s, a job is judged abandoned only after five beats in a row
    did not arrive, while a worker killed mid-job is noticed within lease + one check (12 s).
    """
    return min(max(lease_s / 5, _BEAT_MIN_S), _BEAT_MAX_S)


@dataclass
class TrackedJob:
    """A claimed job inside :func:`tracked_job`: where to write, what to store at the end.

    Attributes:
        runtime: the process's runtime.
        kind: the job's kind.
        job_id: its row id.
        project_id: its project.
        attempt: how often it has been started, this start included.
        progress: writes the stage and fraction done.
        values: the columns stored when the job succeeds (set by :meth:`succeed`).
        finished_here: whether this worker recorded the end (False: a recovered copy owns it).
    """

    runtime: Runtime
    kind: JobKind
    job_id: str
    project_id: str
    attempt: int
    progress: ProgressWriter
    values: dict[str, Any] = field(default_factory=dict)
    finished_here: bool = False
    _staging: Path | None = None

    def staging_dir(self) -> Path:
        """Return a fresh folder (not yet created) to write the artifacts into."""
        self._staging = self.runtime.store.job_staging_dir(self.kind.folder, self.job_id)
        return self._staging

    def publish(self, staging: Path) -> Path:
        """Rename the finished staging folder into place; return the artifacts folder."""
        final = self.runtime.store.publish_job_artifacts(self.kind.folder, self.job_id, staging)
        if final != staging:  # else the files were copied to the store: the folder goes at the end
            self._staging = None
        return final

    def succeed(self, **values: Any) -> None:  # noqa: ANN401
        """Store ``values`` (result, artifacts, ...) when the job ends successfully."""
        self.values = values

    def discard_staging(self) -> None:
        """Remove a staging folder left by a failure."""
        if self._staging is not None:
            shutil.rmtree(self._staging, ignore_errors=True)
            self._staging = None


@contextmanager
def tracked_job(
    runtime: Runtime, kind: str, job_id: str, *, stage: str = "starting"
) -> Iterator[TrackedJob | None]:
    """Run a job's work inside the claim / heartbeat / finish / cleanup sequence.

    Yields ``None`` when another worker has claimed the job (the caller does nothing).
    A :class:`LocevalError` raised inside fails the job with its problem document; any
    other exception is a bug: it is logged with its traceback and the job fails with an
    error id. Leaving normally stores what :meth:`TrackedJob.succeed` was given.
    """
    spec = runtime.kinds[kind]
    try:
        claimed = persist(
            lambda: claim(runtime, spec.model, job_id, stage=stage),
            "claim",
            job_id,
            patience_s=CLAIM_PATIENCE_S,
        )
    except DATABASE_ERRORS as err:  # the row is still queued: the message is queued again
        msg = f"{kind} {job_id} could not be claimed: the database cannot be reached"
        raise JobDeferred(msg) from err
    if claimed is None:
        yield None
        return
    project_id, attempt = claimed
    job = TrackedJob(
        runtime, spec, job_id, project_id, attempt, ProgressWriter(runtime, spec.model, job_id)
    )
    heartbeat = Heartbeat(runtime, spec.model, job_id)
    runtime.active.add(job_id)
    heartbeat.start()
    started = time.monotonic()
    try:
        with log_context(job_id=job_id, kind=kind, project=project_id):
            log_transition("started", kind, job_id, project=project_id, attempt=attempt)
            status, values = JobStatus.SUCCEEDED, job.values
            try:
                yield job
                values = job.values
            except _OUTAGES as err:  # an outage, not the job's failure (a store's outage is
                job.discard_staging()  # a LocevalError too: this clause comes first)
                _defer(runtime, spec, job_id, attempt, err)
                msg = f"{kind} {job_id} was put back: {_unreachable(err)} cannot be reached"
                raise JobDeferred(msg) from err
            except LocevalError as err:
                status, values = (
                    JobStatus.FAILED,
                    {"error": problem_for(err, private=runtime.private_roots)},
                )
            except Exception:  # a bug in the job: it must not kill the consumer thread
                error_id = uuid.uuid4().hex[:12]
                logger.exception("%s %s failed with a bug (error_id=%s)", kind, job_id, error_id)
                status, values = JobStatus.FAILED, {"error": internal_problem(error_id)}
            finally:
                job.discard_staging()
            job.finished_here = _finish_persisted(runtime, spec.model, job_id, status, values)
            log_transition(
                str(status),
                kind,
                job_id,
                level=logging.INFO if status == JobStatus.SUCCEEDED else logging.WARNING,
                project=project_id,
                attempt=attempt,
                duration_s=round(time.monotonic() - started, 3),
                error=values.get("error", {}).get("type") if "error" in values else None,
            )
    finally:  # beats go on until the end is written: a long retry must not look abandoned
        heartbeat.stop()
        runtime.active.discard(job_id)


def _finish_persisted(
    runtime: Runtime, model: JobModel, job_id: str, status: str, values: dict[str, Any]
) -> bool:
    """Record the job's end, retried through an outage; False if it never could be."""
    try:
        return persist(
            lambda: finish(runtime, model, job_id, status=status, **values),
            "finish",
            job_id,
            patience_s=FINISH_PATIENCE_S,
        )
    except DATABASE_ERRORS:
        logger.error(  # noqa: TRY400  (persist logged the cause)
            "The end of %s could not be recorded (the database stayed away %g s); the job "
            "runs again when its lease runs out",
            job_id,
            FINISH_PATIENCE_S,
        )
        return False


def _defer(runtime: Runtime, kind: JobKind, job_id: str, attempt: int, err: Exception) -> None:
    """Put a job back to ``queued`` after an outage (the attempt not counted)."""
    model = kind.model

    def put_back() -> None:
        with runtime.sessions() as session:
            session.execute(
                update(model)
                .where(
                    model.id == job_id,
                    model.status == JobStatus.RUNNING,
                    model.worker == runtime.worker_id,
                )
                .values(
                    status=JobStatus.QUEUED,
                    attempts=model.attempts - 1,
                    worker=None,
                    heartbeat_at=None,
                    stage=f"queued again: {_unreachable(err)} could not be reached",
                    fraction=0.0,
                )
            )
            session.commit()

    log_transition(
        "deferred",
        kind.name,
        job_id,
        level=logging.WARNING,
        attempt=attempt,
        error=type(err).__name__,
    )
    try:
        persist(put_back, "putting back", job_id, patience_s=CLAIM_PATIENCE_S)
    except DATABASE_ERRORS:  # still running without a heartbeat: the lease check re-queues it
        logger.error("%s stays running until its lease runs out", job_id)  # noqa: TRY400


def claim(
    runtime: Runtime, model: JobModel, job_id: str, *, stage: str = "starting"
) -> tuple[str, int] | None:
    """Move a queued job to running for this worker.

    Returns:
        The job's project and attempt number, or None if someone else has it.
    """
    now = utcnow()
    with runtime.sessions() as session:
        claimed = session.execute(
            update(model)
            .where(model.id == job_id, model.status == JobStatus.QUEUED)
            .values(
                status=JobStatus.RUNNING,
                attempts=model.attempts + 1,
                worker=runtime.worker_id,
                heartbeat_at=now,
                started_at=now,
                stage=stage,
                fraction=0.0,
            )
        )
        session.commit()
        if not claimed.rowcount:  # type: ignore[attr-defined]
            return None
        project_id, attempts = session.execute(
            select(model.project_id, model.attempts).where(model.id == job_id)
        ).one()
        return str(project_id), int(attempts)


def finish(
    runtime: Runtime,
    model: JobModel,
    job_id: str,
    *,
    status: str,
    **values: Any,  # noqa: ANN401
) -> bool:
    """Record a job's end, if this worker still holds it (else a recovered copy owns it)."""
    succeeded = status == JobStatus.SUCCEEDED
    with runtime.sessions() as session:
        done = session.execute(
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
        return bool(done.rowcount)  # type: ignore[attr-defined]


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
        try:
            with self.runtime.sessions() as session:
                session.execute(
                    update(self.model)
                    .where(self.model.id == self.job_id)
                    .values(stage=stage[:200], fraction=min(max(fraction, 0.0), 1.0))
                )
                session.commit()
        except DATABASE_ERRORS as err:  # progress is shown, not kept: the work goes on
            self._last, self._stage = 0.0, ""  # write the next one, whatever its stage
            logger.warning("Progress of %s not stored (%s)", self.job_id, type(err).__name__)


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
        interval = beat_interval(self.runtime.settings.job_lease_s)
        model = self.model
        wait, missed = interval, 0
        while not self._stop.wait(wait):
            try:
                with self.runtime.sessions() as session:
                    session.execute(
                        update(model)
                        .where(model.id == self.job_id, model.status == JobStatus.RUNNING)
                        .values(heartbeat_at=utcnow())
                    )
                    session.commit()
            except DATABASE_ERRORS as err:  # a lost beat is retried soon; the job goes on
                if not missed:
                    logger.warning("Heartbeat of %s failed (%s)", self.job_id, type(err).__name__)
                missed += 1
                wait = min(interval, BACKOFF_MAX_S / 4)
            else:
                if missed:
                    logger.warning("Heartbeat of %s back after %d misses", self.job_id, missed)
                wait, missed = interval, 0


# --- recovery --------------------------------------------------------------------------


def recover(
    runtime: Runtime,
    *,
    now: dt.datetime | None = None,
    stale: bool = True,
    lost_after_s: float | None = 60.0,
) -> list[str]:
    """Re-queue or fail jobs whose worker stopped; return the ids that were re-queued.

    A running job (of any kind) whose heartbeat is older than the lease was abandoned: it is
    queued again unless it has been started ``job_attempts`` times, then it fails with the
    reason. A job this process is running is never taken for abandoned. A queued job that
    the queue no longer holds (a Redis without persistence restarted, a retry that could not
    be queued) is enqueued again; the claim makes a duplicate harmless.

    Args:
        runtime: the process's runtime.
        now: the time to judge by (default: now).
        stale: look for abandoned running jobs (the watchdog skips it until the database
            has been reachable for a whole lease: a heartbeat missed during an outage is not
            a dead worker).
        lost_after_s: look for queued jobs older than this that the queue does not hold;
            None: do not look (it lists the queue).
    """
    now = now or utcnow()
    kinds = list(runtime.kinds.values())
    requeued = {kind.name: _requeue_stale(runtime, kind, now) if stale else [] for kind in kinds}
    lost: dict[str, list[str]] = {kind.name: [] for kind in kinds}
    if lost_after_s is not None and not runtime.huey.immediate:
        since = now - dt.timedelta(seconds=lost_after_s)
        queued = {kind.name: _queued_before(runtime, kind.model, since) for kind in kinds}
        if any(queued.values()):
            held = {
                (t.name, str(t.args[0]))
                for t in [*runtime.huey.pending(), *runtime.huey.scheduled()]
                if t.args
            }
            for kind in kinds:
                mine = {job_id for name, job_id in held if name == kind.task_name}
                lost[kind.name] = sorted(queued[kind.name] - mine - set(requeued[kind.name]))
    for kind in kinds:
        for job_id in requeued[kind.name]:
            runtime.enqueue(kind.name, job_id, requeued="interrupted")
        for job_id in lost[kind.name]:
            runtime.enqueue(kind.name, job_id, requeued="not in the queue")
    return [job_id for kind in kinds for job_id in requeued[kind.name] + lost[kind.name]]


def _requeue_stale(runtime: Runtime, kind: JobKind, now: dt.datetime) -> list[str]:
    """Mark abandoned running jobs queued (or failed at the attempt limit); return the queued."""
    model = kind.model
    cutoff = now - dt.timedelta(seconds=runtime.settings.job_lease_s)
    requeued: list[str] = []
    with runtime.sessions() as session:
        stale = session.execute(
            select(
                model.id, model.attempts, model.heartbeat_at, model.project_id, model.worker
            ).where(
                model.status == JobStatus.RUNNING,
                or_(model.heartbeat_at.is_(None), model.heartbeat_at < cutoff),
            )
        ).all()
        for job_id, attempts, beat, project_id, worker in stale:
            if worker == runtime.worker_id and job_id in runtime.active:
                continue  # this process runs it: alive, whatever its heartbeat says
            given_up = attempts >= runtime.settings.job_attempts
            if given_up:
                detail = kind.interrupted_detail.format(n=attempts)
                values: dict[str, Any] = {
                    "status": JobStatus.FAILED,
                    "stage": "failed",
                    "finished_at": now,
                    "error": problem(500, kind.interrupted_code, kind.interrupted_title, detail),
                }
            else:
                values = {
                    "status": JobStatus.QUEUED,
                    "stage": f"queued again after an interruption (attempt {attempts})",
                    "fraction": 0.0,
                }
            done = session.execute(
                update(model)
                .where(
                    model.id == job_id,
                    model.status == JobStatus.RUNNING,
                    model.heartbeat_at == beat,
                )
                .values(**values)
            )
            if not done.rowcount:  # type: ignore[attr-defined]
                continue
            if given_up:
                log_transition(
                    "failed",
                    kind.name,
                    job_id,
                    level=logging.WARNING,
                    project=project_id,
                    attempt=attempts,
                    error=kind.interrupted_code,
                )
            else:
                requeued.append(job_id)
        session.commit()
    return requeued


def _queued_before(runtime: Runtime, model: JobModel, since: dt.datetime) -> set[str]:
    """Return the jobs queued before ``since`` (candidates for a lost queue entry)."""
    with runtime.sessions() as session:
        return set(
            session.scalars(
                select(model.id).where(
                    model.status == JobStatus.QUEUED,
                    model.created_at < since,
                )
            ).all()
        )


def release(runtime: Runtime) -> int:
    """Queue again the jobs this process was running when it stopped; return how many.

    Their threads are abandoned (daemon threads end with the process); whatever they still
    write is ignored, because a finished job is recorded only by the worker that holds it.
    """
    released = 0
    for kind in runtime.kinds.values():
        model = kind.model
        with runtime.sessions() as session:
            ids = session.scalars(
                select(model.id).where(
                    model.status == JobStatus.RUNNING, model.worker == runtime.worker_id
                )
            ).all()
            session.execute(
                update(model)
                .where(
                    model.id.in_(ids),
                    model.status == JobStatus.RUNNING,
                    model.worker == runtime.worker_id,
                )
                .values(
                    status=JobStatus.QUEUED,
                    worker=None,
                    heartbeat_at=None,
                    stage="queued again: the service stopped while it ran",
                    fraction=0.0,
                )
            )
            session.commit()
        for job_id in ids:
            runtime.enqueue(kind.name, job_id, requeued="service stopped")
        released += len(ids)
    return released
