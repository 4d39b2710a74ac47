"""The queue wiring: a process's runtime, with every entry of the registry as a huey task.

:func:`create_runtime` opens a process's :class:`~service.runtime.Runtime` and turns each
job kind, retried task and periodic task of :mod:`service.jobs.kinds` into a huey task. Every
executor runs inside :func:`service.jobs.tracking.tracked_job` (claim, heartbeat, finish,
cleanup), so a kind is only what differs: what it reads and what it stores.
"""

from __future__ import annotations

import os
import socket
import uuid
from typing import Any, Final

from huey import crontab
from huey.exceptions import RetryTask

from service.blobs import open_blobs
from service.db import create_db_engine, make_session_factory
from service.jobs.kinds import JOB_KINDS, PERIODIC_TASKS, WEBHOOK, PeriodicTask, RetriedTask
from service.jobs.limits import warm_up
from service.jobs.tracking import JobDeferred, release
from service.jobs.watchdog import start_watchdog
from service.preflight import check_data_dir, prepare_schema
from service.runtime import JobKind, Runtime, create_huey, load_target
from service.settings import Settings

__all__ = ["create_runtime"]

_DEFERRED_DELAY_S: Final = 2.0
"""When a job put off by a database outage is tried again (its thread waited 30 s already)."""


def create_runtime(settings: Settings, *, apply_migrations: bool = True) -> Runtime:
    """Open the database (migrated to the newest schema), the blob store and the queue.

    The start-up checks run first (:mod:`service.preflight`): the data directory must be
    writable and the database not newer than this code.

    Each job kind becomes a queue task named ``run_<kind>`` whose only argument is the job
    id; webhooks of finished runs are the task ``deliver_webhook`` (retried by the queue);
    ``every_minute`` recovers abandoned jobs and fires due schedules; ``retention_sweep``
    (hourly) deletes expired evaluations and orphaned files (:mod:`service.jobs.retention`).

    Raises:
        StartupError: the data directory is not writable, or the database is at a migration
            this code does not know.
    """
    check_data_dir(settings)  # raises when unusable; the low-space warning is the callers'
    engine = create_db_engine(settings.resolved_database_url)
    try:
        prepare_schema(engine, apply_migrations=apply_migrations)
    except BaseException:
        engine.dispose()
        raise
    runtime = Runtime(
        settings=settings,
        engine=engine,
        sessions=make_session_factory(engine),
        store=open_blobs(settings),
        huey=create_huey(settings),
        worker_id=f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:6]}",
        kinds={kind.name: kind for kind in JOB_KINDS},
        release=release,
        watch=lambda r: start_watchdog(r).stop,
        warm_up=warm_up,
    )
    for kind in JOB_KINDS:
        runtime.tasks[kind.name] = _job_task(runtime, kind)
    runtime.tasks[WEBHOOK.name] = _retried_task(runtime, WEBHOOK)
    for periodic in PERIODIC_TASKS:
        _periodic_task(runtime, periodic)
    return runtime


def _job_task(runtime: Runtime, kind: JobKind) -> Any:  # noqa: ANN401  (huey's TaskWrapper)
    """Return the queue task that runs jobs of ``kind`` in ``runtime``."""

    @runtime.huey.task(name=kind.task_name)  # type: ignore[untyped-decorator]
    def run(job_id: str) -> None:
        try:
            kind.execute(runtime, job_id)
        except JobDeferred as err:  # the database was away: the row is queued, so is this
            raise RetryTask(str(err), delay=_DEFERRED_DELAY_S) from err

    return run


def _retried_task(runtime: Runtime, spec: RetriedTask) -> Any:  # noqa: ANN401  (TaskWrapper)
    """Return the queue task of ``spec``: tried again by the queue, with a growing delay."""
    huey = runtime.huey

    # Immediate mode runs a retry at once (the queue has no consumer to wait for the delay).
    @huey.task(  # type: ignore[untyped-decorator]
        name=spec.task_name,
        retries=spec.attempts - 1,
        retry_delay=0 if huey.immediate else spec.retry_delay_s,
        retry_backoff=2,
        context=True,
    )
    def attempt(job_id: str, task: Any = None) -> None:  # noqa: ANN401  (huey's Task)
        load_target(spec.target)(runtime, job_id, attempt=spec.attempts - int(task.retries))

    return attempt


def _periodic_task(runtime: Runtime, spec: PeriodicTask) -> None:
    """Register the periodic task of ``spec``: its steps in order, on its clock."""

    @runtime.huey.periodic_task(crontab(minute=spec.minute), name=spec.task_name)  # type: ignore[untyped-decorator]
    def run() -> None:
        for target in spec.targets:
            load_target(target)(runtime)
