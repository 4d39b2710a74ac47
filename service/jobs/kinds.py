"""Every task of the queue and every kind of request, by name: one typed registry.

:data:`JOB_KINDS` holds the kinds of tracked job (their table, artifact folder and
executor), :data:`REQUEST_KINDS` the kinds of an evaluation's request (its model and the job
made from it; a row records its request's kind, which is read here, never guessed from the
request), :data:`WEBHOOK` and :data:`PERIODIC_TASKS` the queue's other tasks.

One typed registry, in the shape of :data:`exporters.ARTIFACTS`: each entry names the function
that runs it as ``"module:function"``, imported when a task of it first runs. So the registry
lists the work of every folder (evaluations here in ``jobs/``, schedule runs, their webhooks
and the schedules' tick in ``schedules/``, which builds on ``jobs/``) without importing it,
and importing it loads no executor. :func:`service.jobs.queue.create_runtime` turns each
entry into a huey task; ``tests/test_layering.py`` checks that every target imports.

The ``task_name`` of an entry is stored in queued messages: never rename one.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

from loceval.errors import LocevalError
from service.blobs.base import EVALUATIONS, RUNS
from service.db import Evaluation, ScheduleRun
from service.runtime import JobKind
from service.schemas.evaluations import EvaluationCreate, RangingCreate

__all__ = [
    "EVALUATION",
    "JOB_KINDS",
    "PERIODIC_TASKS",
    "RANGING",
    "REQUEST_KINDS",
    "RUN",
    "TRAJECTORY",
    "WEBHOOK",
    "PeriodicTask",
    "RequestKind",
    "RetriedTask",
    "request_kind",
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


TRAJECTORY: Final = "trajectory"
"""An evaluation of trajectories (or of control points) against a reference."""
RANGING: Final = "ranging"
"""An evaluation of radio ranges and of the positions solved from them."""


@dataclass(frozen=True, slots=True)
class RequestKind:
    """One kind of an evaluation's request: what it is read as, and what job it makes.

    Attributes:
        name: its key, stored with each evaluation (``evaluations.kind``).
        model: the request body; a stored request is read again as it, checked as when made.
        job: ``"module:function"`` making the job from the stored evaluation, called as
            ``function(session, runtime, evaluation, request)``.
        job_kind: the kind of tracked job that runs it (its table, artifact folder and
            executor: :data:`JOB_KINDS`).
        listed: keys the stored copy adds for the evaluations list, which the model does not
            take (a ranging request lists its solvers as its estimates).
    """

    name: str
    model: type[EvaluationCreate | RangingCreate]
    job: str
    job_kind: str = EVALUATION
    listed: tuple[str, ...] = ()

    def read(self, request: Mapping[str, Any]) -> EvaluationCreate | RangingCreate:
        """Read a stored request as this kind's model.

        Raises:
            pydantic.ValidationError: the stored request no longer fits its model.
        """
        return self.model.model_validate(
            {key: value for key, value in request.items() if key not in self.listed}
        )


REQUEST_KINDS: Final[Mapping[str, RequestKind]] = {
    kind.name: kind
    for kind in (
        RequestKind(TRAJECTORY, EvaluationCreate, "service.jobs.executor:trajectory_job"),
        RequestKind(
            RANGING, RangingCreate, "service.jobs.executor:ranging_job", listed=("estimates",)
        ),
    )
}
"""Every kind of request an evaluation can have, by name."""


def request_kind(name: str) -> RequestKind:
    """Return the request kind an evaluation records.

    Raises:
        LocevalError: no such kind (a row written by a newer version of the service).
    """
    kind = REQUEST_KINDS.get(name)
    if kind is None:
        msg = (
            f"The evaluation's request is of the kind {name!r}, which this version of the "
            f"service does not know ({', '.join(REQUEST_KINDS)}); run it on a newer one."
        )
        raise LocevalError(msg)
    return kind


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
            "service.uploads.tus:sweep_expired",  # resumable uploads past their expiry
        ),
    ),
    PeriodicTask(
        task_name="retention_sweep",
        minute="17",
        targets=("service.jobs.retention:sweep",),  # expired evaluations and orphaned files
    ),
)
"""Every periodic task."""
