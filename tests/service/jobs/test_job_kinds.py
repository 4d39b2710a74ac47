"""The job registry, and webhook delivery as a queue task retried by the queue itself."""

from __future__ import annotations

import datetime as dt
import json
from collections.abc import Iterator
from pathlib import Path

import pytest
import sqlalchemy as sa
from alembic import command
from alembic.config import Config
from pydantic import ValidationError

from loceval.errors import LocevalError
from service import db
from service.blobs.base import EVALUATIONS, RUNS
from service.db import Evaluation, Project, ScheduleRun, create_db_engine, migrate, utcnow
from service.jobs.executor import stored_request
from service.jobs.kinds import JOB_KINDS, PERIODIC_TASKS, REQUEST_KINDS
from service.jobs.kinds import WEBHOOK as WEBHOOK_TASK
from service.jobs.queue import create_runtime
from service.runtime import Runtime, load_target
from service.schedules.runs import WEBHOOK
from service.schemas.evaluations import EvaluationCreate, RangingCreate
from service.settings import Settings
from tests.service._job_rows import add_schedule_run
from tests.service.schedules.test_schedules_api import _Hook


@pytest.fixture
def runtime(tmp_path: Path) -> Iterator[Runtime]:
    """A runtime on huey's SQLite queue with no consumer: tasks wait until executed here."""
    rt = create_runtime(Settings(data_dir=tmp_path / "data", webhook_allow="127.0.0.1"))
    yield rt
    rt.close()


def test_each_kind_has_its_table_folder_and_a_stable_task_name() -> None:
    """Queued messages name the task: the names stay those of earlier releases."""
    table = {k.name: (k.model, k.folder, k.task_name) for k in JOB_KINDS}
    assert table == {
        "evaluation": (Evaluation, EVALUATIONS, "run_evaluation"),
        "run": (ScheduleRun, RUNS, "run_schedule"),
    }
    assert all("{n}" in k.interrupted_detail for k in JOB_KINDS)


def test_every_target_of_the_registry_imports() -> None:
    """Each executor and task step the registry names is a function that imports."""
    targets = [
        *(k.executor for k in JOB_KINDS),
        WEBHOOK_TASK.target,
        *(step for task in PERIODIC_TASKS for step in task.targets),
    ]
    assert all(callable(load_target(target)) for target in targets)
    assert WEBHOOK_TASK.name == WEBHOOK
    with pytest.raises(AttributeError):
        load_target("service.jobs.executor:no_such_executor")


def test_a_stored_request_is_read_as_its_recorded_kind(tmp_path: Path) -> None:
    """The row says its kind; the registry reads the request as that kind's model."""
    runtime = create_runtime(Settings(data_dir=tmp_path / "data", queue_url="immediate"))
    ranging = {
        "reference": {"dataset_id": "r"},
        "anchors": "a",
        "ranges": {"dataset_id": "g"},
        "options": {},
        "estimates": [{"dataset_id": "g", "selector": None, "name": "nlls"}],
    }
    trajectory = {"reference": {"dataset_id": "r"}, "estimates": [{"dataset_id": "e"}]}
    try:
        with runtime.sessions() as session:
            project = Project(name="site")
            session.add(project)
            session.flush()
            rows = [
                Evaluation(project_id=project.id, kind=kind, request=request)
                for kind, request in (("ranging", ranging), ("trajectory", trajectory))
            ]
            session.add_all(rows)
            session.commit()
            assert isinstance(stored_request(rows[0]), RangingCreate)
            assert isinstance(stored_request(rows[1]), EvaluationCreate)
            rows[1].kind = "ranging"  # the kind decides, not the request's keys
            with pytest.raises(ValidationError, match="anchors"):
                stored_request(rows[1])
            rows[1].kind = "teleport"
            with pytest.raises(LocevalError, match=r"kind 'teleport'.*does not know"):
                stored_request(rows[1])
    finally:
        runtime.close()
    assert {k.job_kind for k in REQUEST_KINDS.values()} <= {k.name for k in JOB_KINDS}
    assert all(callable(load_target(k.job)) for k in REQUEST_KINDS.values())


def test_the_migration_records_the_kind_of_earlier_evaluations(tmp_path: Path) -> None:
    """Evaluations stored before 0004 get their kind: ranging where the request names anchors."""
    engine = create_db_engine(f"sqlite:///{tmp_path / 'old.db'}")
    config = Config()
    config.set_main_option("script_location", str(Path(db.__file__).parent / "migrations"))
    now = "2026-01-01 00:00:00.000000"
    with engine.begin() as connection:
        config.attributes["connection"] = connection
        command.upgrade(config, "0003")
        connection.execute(
            sa.text("INSERT INTO projects (id, name, created_at) VALUES ('p', 'site', :now)"),
            {"now": now},
        )
        for evaluation_id, request in (("e1", {"reference": {}}), ("e2", {"anchors": "a"})):
            connection.execute(
                sa.text(
                    "INSERT INTO evaluations (id, project_id, request, dataset_ids, status, "
                    "stage, fraction, attempts, created_at) VALUES "
                    "(:id, 'p', :request, '[]', 'succeeded', 'done', 1.0, 1, :now)"
                ),
                {"id": evaluation_id, "request": json.dumps(request), "now": now},
            )
    migrate(engine)
    with engine.connect() as connection:
        kinds = dict(connection.execute(sa.text("SELECT id, kind FROM evaluations")).all())
    engine.dispose()
    assert kinds == {"e1": "trajectory", "e2": "ranging"}


def _finished_run(rt: Runtime, webhook_url: str) -> str:
    """Record a succeeded schedule run whose schedule posts to ``webhook_url``."""
    return add_schedule_run(
        rt,
        project_name="site",
        webhook_url=webhook_url,
        trigger="manual",
        status="succeeded",
        rows=[],
        finished_at=utcnow(),
    )


def test_a_failed_webhook_is_retried_by_the_queue_not_by_sleeping(runtime: Runtime) -> None:
    """Each attempt is one task execution; a failure is rescheduled 2 s, then 4 s later."""
    hook = _Hook(503)
    try:
        run_id = _finished_run(runtime, hook.url)
        runtime.enqueue(WEBHOOK, run_id)
        delays_s: list[float] = []
        executed_at: dt.datetime | None = None
        for _attempt in range(3):
            (task,) = [*runtime.huey.pending(), *runtime.huey.scheduled()]
            assert (task.name, task.args) == ("deliver_webhook", (run_id,))
            if executed_at is not None:
                delays_s.append((task.eta - executed_at).total_seconds())
            runtime.huey.storage.flush_all()  # take it out of the queue, as a consumer does
            # The consumer runs a retry at its eta; here it runs at once (timestamp=eta), and
            # huey counts the next eta from the wall clock when the attempt failed.
            executed_at = dt.datetime.now(dt.UTC).replace(tzinfo=None)  # huey's naive UTC
            runtime.huey.execute(task, timestamp=task.eta or executed_at)
        assert not runtime.huey.pending()
        assert not runtime.huey.scheduled()  # no fourth attempt
    finally:
        hook.close()
    assert len(hook.bodies) == 3
    assert delays_s == [pytest.approx(2.0, abs=0.5), pytest.approx(4.0, abs=0.5)]  # 2 s, x2
    with runtime.sessions() as session:
        record = session.get_one(ScheduleRun, run_id).webhook
    assert record is not None
    assert record["delivered"] is False
    assert [a["status"] for a in record["attempts"]] == [503, 503, 503]


def test_a_delivered_webhook_runs_once(runtime: Runtime) -> None:
    """A 2xx answer records delivered after one attempt and schedules nothing more."""
    hook = _Hook(204)
    try:
        run_id = _finished_run(runtime, hook.url)
        runtime.enqueue(WEBHOOK, run_id)
        (task,) = runtime.huey.pending()
        runtime.huey.storage.flush_all()
        runtime.huey.execute(task)
        assert not runtime.huey.scheduled()
    finally:
        hook.close()
    (payload,) = hook.bodies
    assert payload["run"]["id"] == run_id
    with runtime.sessions() as session:
        record = session.get_one(ScheduleRun, run_id).webhook
    assert record is not None
    assert record["delivered"] is True
    assert [a["status"] for a in record["attempts"]] == [204]
