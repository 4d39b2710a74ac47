"""What a service or worker process shares: settings, database, blobs, the queue, job kinds.

This module knows no job kind by name: the kinds (evaluations, schedule runs) are given to
:class:`Runtime` by :func:`service.jobs.queue.create_runtime`, which wires them to the
queue. Code that runs or queues a job does it through the runtime
(``runtime.enqueue("evaluation", id)``), so no job module imports another job module to reach
its executor.
"""

from __future__ import annotations

import importlib
import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from huey import Huey, MemoryHuey, RedisHuey, SqliteHuey
from huey.consumer import Consumer
from sqlalchemy import Engine
from sqlalchemy.orm import Session, sessionmaker

from service.adapters import converted
from service.blobs import Blobs
from service.db import Evaluation, ScheduleRun
from service.logs import log_transition
from service.settings import Settings

__all__ = ["JobKind", "JobModel", "Runtime", "create_huey", "load_target"]

logger = logging.getLogger(__name__)

_CONSUMER_SHUTDOWN_S: Final = 10.0

JobModel = type[Evaluation] | type[ScheduleRun]
"""A table of queued jobs (both have the :class:`~service.db.JobState` columns)."""


def load_target(target: str) -> Callable[..., Any]:
    """Import and return the function that ``"module:function"`` names.

    Raises:
        ImportError: the module cannot be imported.
        AttributeError: it has no such function.
    """
    module_name, _, name = target.partition(":")
    function: Callable[..., Any] = getattr(importlib.import_module(module_name), name)
    return function


@dataclass(frozen=True)
class JobKind:
    """One kind of tracked job: its table, its storage folder, what runs it, how it ends.

    Attributes:
        name: the kind's key (``"evaluation"``, ``"run"``); also in log lines.
        task_name: the queue task that runs it (stored in queued messages: never rename).
        model: the table holding the job's state.
        folder: the blob store folder of its artifacts (``evaluations``, ``runs``).
        executor: ``"module:function"`` of what runs one job to its end (never raising for
            the job's own failures), imported when a job of the kind first runs, so the
            registry names kinds of every folder without importing them
            (:data:`service.jobs.kinds.JOB_KINDS`).
        interrupted_code: problem type of a job given up after repeated interruptions.
        interrupted_title: problem title of that failure.
        interrupted_detail: its detail, with ``{n}`` for the number of interruptions.
    """

    name: str
    task_name: str
    model: JobModel
    folder: str
    executor: str
    interrupted_code: str
    interrupted_title: str
    interrupted_detail: str

    def execute(self, runtime: Runtime, job_id: str) -> None:
        """Run one job of this kind to its end."""
        load_target(self.executor)(runtime, job_id)


@dataclass
class Runtime:
    """What a service or worker process shares: settings, database, blobs and the queue.

    Attributes:
        settings: the process's settings.
        engine: the metadata database.
        sessions: its session factory.
        store: uploads and artifacts.
        huey: the queue.
        worker_id: this process's name in job rows (``host:pid:random``).
        kinds: the job kinds by name.
        tasks: the queue task of each job kind by kind name, and ``"webhook"``.
        release: queues again the jobs this process still runs when it stops
            (:func:`service.jobs.tracking.release`; given by the wiring, which knows both).
        watch: starts the re-queue check of a consumer process and returns what stops it
            (:func:`service.jobs.watchdog.start_watchdog`; given by the wiring).
        warm_up: prepares the jobs' processes before a consumer starts
            (:func:`service.jobs.limits.warm_up`; given by the wiring).
        active: the ids of the jobs this process is running now (never judged abandoned).
    """

    settings: Settings
    engine: Engine
    sessions: sessionmaker[Session]
    store: Blobs
    huey: Huey
    worker_id: str
    kinds: Mapping[str, JobKind] = field(default_factory=dict)
    tasks: dict[str, Callable[[str], object]] = field(default_factory=dict)
    release: Callable[[Runtime], int] = lambda _runtime: 0
    watch: Callable[[Runtime], Callable[[], None]] = lambda _runtime: lambda: None
    warm_up: Callable[[], None] = lambda: None
    active: set[str] = field(default_factory=set)
    _unwatch: Callable[[], None] | None = None

    @property
    def private_roots(self) -> tuple[Path, ...]:
        """The server's folders no message to a client may show: the blob store's data folder.

        Every problem built for a client or stored with a job is scrubbed of them
        (:func:`service.errors.problem_for`); they belong to this runtime, not the process.
        """
        return self.store.private_roots

    def enqueue(self, kind: str, job_id: str, *, requeued: str | None = None) -> None:
        """Queue a job of a kind (in immediate mode: run it now).

        Args:
            kind: the job kind's name.
            job_id: the job's row id.
            requeued: why a job is queued again (``"interrupted"``, ``"stop"``), if it is.

        Raises:
            ServiceUnavailableError: the queue cannot be reached.
        """
        if requeued is None:
            log_transition("queued", kind, job_id)
        else:
            log_transition("requeued", kind, job_id, level=logging.WARNING, reason=requeued)
        with converted("queue"):
            self.tasks[kind](job_id)

    def run_inline(self, kind: str, job_id: str) -> None:
        """Run a queued job in this thread (a schedule run runs its evaluations so)."""
        self.kinds[kind].execute(self, job_id)

    def start_consumer(self, *, periodic: bool = True) -> Consumer:
        """Start queue consumer threads in this process (no signal handlers of its own).

        Logging is the process's entry point's to configure (the app's start, ``loceval
        worker``), once.
        """
        self.warm_up()  # the jobs' forkserver imports the evaluation modules now, not at a job
        consumer = _EmbeddedConsumer(
            self.huey,
            workers=self.settings.workers,
            worker_type="thread",
            periodic=periodic,
            max_delay=2.0,
            check_worker_health=True,
            shutdown_timeout=_CONSUMER_SHUTDOWN_S,
        )
        consumer.start()
        self._unwatch = self.watch(self)
        return consumer

    def stop_consumer(self, consumer: Consumer) -> None:
        """Stop the consumer (running jobs get 10 s) and queue again what did not finish."""
        if self._unwatch is not None:
            self._unwatch()
            self._unwatch = None
        consumer.stop(graceful=True)
        released = self.release(self)
        if released:
            logger.warning("Queued %d unfinished jobs again for the next start", released)

    def close(self) -> None:
        """Release the database connections and the data directory's lock."""
        self.engine.dispose()
        self.store.close()


class _EmbeddedConsumer(Consumer):  # type: ignore[misc]
    """huey's consumer without its signal handlers: uvicorn owns the signals in ``serve``."""

    def _set_signal_handlers(self) -> None:
        """Leave the process's signal handlers alone."""


def create_huey(settings: Settings) -> Huey:
    """Return the queue the settings name: immediate (in memory), Redis or SQLite."""
    if settings.queue_url == "immediate":
        return MemoryHuey("loceval", immediate=True, results=False)
    if settings.queue_url.startswith(("redis://", "rediss://")):
        return RedisHuey("loceval", url=settings.queue_url, results=False)
    queue_db = (settings.data_dir / "queue.db").resolve()
    return SqliteHuey("loceval", filename=str(queue_db), results=False, timeout=30)
