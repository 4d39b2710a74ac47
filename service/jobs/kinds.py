"""Every task of the queue, by name: the kinds of tracked job, the retried and periodic tasks.

One typed registry, in the shape of :data:`exporters.ARTIFACTS`: each entry names the function
that runs it as ``"module:function"``, imported when a task of it first runs. So the registry
lists the work of every folder (evaluations here in ``jobs/``, schedule runs, their webhooks
and the schedules' tick in ``schedules/``, which builds on ``jobs/``) without importing it,
and importing it loads no executor. :func:`service.jobs.queue.create_runtime` turns each
entry into a huey task; ``tests/test_layering.py`` checks that every target imports.

The ``task_name`` of an entry is stored in queued messages: never rename one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from service.blobs.base import EVALUATIONS, RUNS
from service.db import Evaluation, ScheduleRun
from service.runtime import JobKind

__all__ = [
    "EVALUATION",
    "JOB_KINDS",
    "PERIODIC_TASKS",
    "RUN",
    "WEBHOOK",
    "PeriodicTask",
    "RetriedTask",
]

EVALUATION: Final = "evaluation"
"""The job kind of evaluations (a trajectory, control-point or ranging evaluation)."""
RUN: Final = "run"
"""The job kind of schedule runs."""

JOB_KINDS: Final = (
    JobKind(
        name=EVALUATION,
        task_name="run_evaluation",
        model=Evaluation,
        folder=EVALUATIONS,
        executor="service.jobs.executor:execute_evaluation",
        interrupted_code="evaluation.interrupted",
        interrupted_title="JobInterrupted",
        interrupted_detail=(
            "The evaluation was interrupted {n} times (its worker stopped: a crash, a restart "
            "or running out of memory) and is not retried again; check the server log, and "
            "give the server more memory for very large recordings."
        ),
    ),
    JobKind(
        name=RUN,
        task_name="run_schedule",
        model=ScheduleRun,
        folder=RUNS,
        executor="service.schedules.runs:execute_schedule_run",
        interrupted_code="run.interrupted",
        interrupted_title="RunInterrupted",
        interrupted_detail=(
            "The run was interrupted {n} times (its worker stopped) and is not retried again; "
            "check the server log."
        ),
    ),
)
"""Every kind of tracked job."""


@dataclass(frozen=True, slots=True)
class RetriedTask:
    """A queue task that is no tracked job and that the queue itself retries.

    Attributes:
        name: its key in :attr:`service.runtime.Runtime.tasks` (``runtime.enqueue(name, id)``).
        task_name: the huey task's name (stored in queued messages).
        target: ``"module:function"`` called as ``function(runtime, job_id, attempt=n)``
            (``n`` counts from 1); it raises to be tried again.
        attempts: how often it runs at most.
        retry_delay_s: the wait before the second attempt; each later one waits twice as long.
    """

    name: str
    task_name: str
    target: str
    attempts: int
    retry_delay_s: float


WEBHOOK: Final = RetriedTask(
    name="webhook",
    task_name="deliver_webhook",
    target="service.schedules.runs:deliver_webhook",
    attempts=3,
    retry_delay_s=2.0,  # then 4 s, as before the queue did it
)
"""A finished schedule run's webhook, one post per attempt."""


@dataclass(frozen=True, slots=True)
class PeriodicTask:
    """Work the queue's consumers run on a clock.

    Attributes:
        task_name: the huey task's name.
        minute: the crontab minute field (``"*"``: every minute; ``"17"``: hourly at :17).
        targets: ``"module:function"`` of each step, called in order as ``function(runtime)``.
    """

    task_name: str
    minute: str
    targets: tuple[str, ...]


PERIODIC_TASKS: Final = (
    PeriodicTask(
        task_name="every_minute",
        minute="*",
        targets=(
            "service.jobs.tracking:recover",  # abandoned jobs queued again or failed
            "service.schedules.resource:tick",  # due schedules fired
            "service.jobs.retention:sweep_leftovers",  # abandoned uploads and staging folders
        ),
    ),
    PeriodicTask(
        task_name="retention_sweep",
        minute="17",
        targets=("service.jobs.retention:sweep",),  # expired evaluations and orphaned files
    ),
)
"""Every periodic task."""
