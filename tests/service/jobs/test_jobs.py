"""Evaluation jobs: claiming, failing with problems, recovery after crashes, migrations."""

from __future__ import annotations

import datetime as dt
import json
import logging
from pathlib import Path

import pytest
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import inspect, select
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session

from service.db import Base, Evaluation, Project, ScheduleRun, utcnow
from service.jobs import executor as jobs
from service.jobs.executor import execute_evaluation
from service.jobs.queue import create_runtime
from service.jobs.tracking import recover, release
from service.runtime import Runtime
from service.settings import Settings
from tests.factories import make_trajectory, write_tum
from tests.service import _job_hooks as hooks
from tests.service._job_rows import add_dataset, add_schedule_run


@pytest.fixture
def runtime(tmp_path: Path):
    """A runtime on SQLite with huey's SQLite queue and no consumer: jobs wait in the queue."""
    rt = create_runtime(Settings(data_dir=tmp_path / "data", job_lease_s=30, job_attempts=3))
    yield rt
    rt.close()


@pytest.fixture
def evaluation_id(runtime: Runtime, tmp_path: Path, rng) -> str:
    """A queued evaluation of a synthetic estimate against its ground truth."""
    truth = make_trajectory(rng, 200)
    gt = write_tum(tmp_path / "gt.txt", truth)
    est = write_tum(tmp_path / "est.txt", truth)
    with runtime.sessions() as session:
        project = Project(name="site")
        session.add(project)
        session.commit()
    ref_id = add_dataset(runtime, project.id, gt)
    est_id = add_dataset(runtime, project.id, est)
    with runtime.sessions() as session:
        evaluation = Evaluation(
            project_id=project.id,
            request={
                "reference": {"dataset_id": ref_id, "selector": None, "name": "truth"},
                "estimates": [{"dataset_id": est_id, "selector": None, "name": "copy"}],
                "options": {"formats": ["errors.csv"]},
            },
            dataset_ids=[ref_id, est_id],
        )
        session.add(evaluation)
        session.commit()
        return evaluation.id


def _row(rt: Runtime, evaluation_id: str) -> Evaluation:
    with rt.sessions() as session:
        return session.get_one(Evaluation, evaluation_id)


def test_migrations_match_the_models(runtime: Runtime):
    """The Alembic migrations create exactly the tables and columns the models declare."""
    with runtime.engine.connect() as connection:
        diff = compare_metadata(MigrationContext.configure(connection), Base.metadata)
    assert diff == []
    assert {"projects", "api_keys", "datasets", "evaluations", "alembic_version"} <= set(
        inspect(runtime.engine).get_table_names()
    )


def test_migrations_are_idempotent(tmp_path: Path):
    """Opening the same database twice applies nothing new and keeps the data."""
    settings = Settings(data_dir=tmp_path)
    first = create_runtime(settings)
    with first.sessions() as session:
        session.add(Project(name="kept"))
        session.commit()
    first.close()
    second = create_runtime(settings)
    with second.sessions() as session:
        assert session.scalar(select(Project.name)) == "kept"
    second.close()


def test_job_succeeds_and_publishes_artifacts(runtime: Runtime, evaluation_id: str):
    """A job runs to succeeded with the result document, summary and only its formats."""
    execute_evaluation(runtime, evaluation_id)
    row = _row(runtime, evaluation_id)
    assert row.status == "succeeded"
    assert (row.stage, row.fraction, row.attempts) == ("done", 1.0, 1)
    assert row.result is not None
    assert row.result["estimates"][0]["name"] == "copy"
    assert row.summary is not None
    assert row.summary[0]["ate_rmse_m"] == pytest.approx(0.0, abs=1e-9)
    assert [a["name"] for a in row.artifacts or []] == ["result.json", "errors.csv"]
    folder = runtime.store.evaluations / evaluation_id
    assert sorted(p.name for p in folder.iterdir()) == ["artifacts"]  # no staging left
    assert row.result["inputs"][0]["path"] == "gt.txt"  # no server path in the result
    assert str(runtime.store.root) not in json.dumps(row.result)
    assert row.result["reference"]["source"] == "tum:gt.txt"
    report = (runtime.store.artifacts_dir(evaluation_id) / "errors.csv").read_text()
    assert str(runtime.store.root) not in report


def test_a_claimed_job_does_not_run_twice(runtime: Runtime, evaluation_id: str, monkeypatch):
    """A job enqueued twice (recovery races a slow worker) runs once: the claim is atomic."""
    execute_evaluation(runtime, evaluation_id)
    calls = []
    monkeypatch.setattr(jobs, "run_job", lambda *a, **_k: calls.append(a))
    execute_evaluation(runtime, evaluation_id)
    assert calls == []
    assert _row(runtime, evaluation_id).attempts == 1


def test_bad_input_fails_the_job_with_the_core_message(
    runtime: Runtime, evaluation_id: str, monkeypatch
):
    """A LocevalError becomes a failed job with a problem document and no half artifacts."""
    monkeypatch.setattr(jobs, "run_job", hooks.no_overlap)  # raised in the job's process
    execute_evaluation(runtime, evaluation_id)
    row = _row(runtime, evaluation_id)
    assert row.status == "failed"
    assert row.error is not None
    assert row.error["type"] == "association.no_matches"
    assert row.error["status"] == 422
    assert row.error["detail"] == "options.time_offset_s: No overlap in est.txt; time offset?"
    assert row.error["option"] == "options.time_offset_s"  # the API's name of the option
    assert row.stage == "starting"  # the stage it failed in is kept
    assert not runtime.store.artifacts_dir(evaluation_id).exists()


def test_a_bug_fails_the_job_with_an_error_id(
    runtime: Runtime, evaluation_id: str, monkeypatch, caplog
):
    """Any other exception is logged with its traceback; the job shows only an error id."""
    monkeypatch.setattr(jobs, "run_job", hooks.crash)  # raised in the job's process
    with caplog.at_level(logging.ERROR, logger="service.jobs"):
        execute_evaluation(runtime, evaluation_id)
    row = _row(runtime, evaluation_id)
    assert row.status == "failed"
    assert row.error is not None
    assert row.error["type"] == "internal"
    assert row.error["error_id"] in row.error["detail"]
    assert "boom" not in row.error["detail"]
    assert row.error["error_id"] in caplog.text
    assert "RuntimeError: boom" in caplog.text


def _abandon(rt: Runtime, evaluation_id: str, *, attempts: int, beat_age_s: float) -> None:
    """Make the row look like a worker died while running it."""
    with rt.sessions() as session:
        row = session.get_one(Evaluation, evaluation_id)
        row.status = "running"
        row.attempts = attempts
        row.worker = "dead-host:1:abc"
        row.heartbeat_at = utcnow() - dt.timedelta(seconds=beat_age_s)
        session.commit()


def test_recover_requeues_an_abandoned_job(runtime: Runtime, evaluation_id: str):
    """A running job whose heartbeat stopped is queued again, and then runs to the end."""
    _abandon(runtime, evaluation_id, attempts=1, beat_age_s=120)
    assert recover(runtime) == [evaluation_id]
    row = _row(runtime, evaluation_id)
    assert row.status == "queued"
    assert "interruption" in row.stage
    assert [t.args for t in runtime.huey.pending()] == [(evaluation_id,)]
    execute_evaluation(runtime, evaluation_id)
    row = _row(runtime, evaluation_id)
    assert (row.status, row.attempts) == ("succeeded", 2)


def test_recover_leaves_live_jobs_alone(runtime: Runtime, evaluation_id: str):
    """A running job with a fresh heartbeat belongs to a live worker and is not touched."""
    _abandon(runtime, evaluation_id, attempts=1, beat_age_s=5)
    assert recover(runtime) == []
    assert _row(runtime, evaluation_id).status == "running"


def test_recover_fails_a_job_after_the_attempt_limit(runtime: Runtime, evaluation_id: str):
    """A job interrupted job_attempts times fails with the reason instead of looping."""
    _abandon(runtime, evaluation_id, attempts=3, beat_age_s=120)
    assert recover(runtime) == []
    row = _row(runtime, evaluation_id)
    assert row.status == "failed"
    assert row.error is not None
    assert row.error["type"] == "evaluation.interrupted"
    assert "interrupted 3 times" in row.error["detail"]
    assert runtime.huey.pending_count() == 0


def test_recover_requeues_a_job_the_queue_lost(runtime: Runtime, evaluation_id: str):
    """A queued job missing from the queue (a Redis restart) is enqueued again, once."""
    with runtime.sessions() as session:
        row = session.get_one(Evaluation, evaluation_id)
        row.created_at = utcnow() - dt.timedelta(minutes=5)
        session.commit()
    assert recover(runtime) == [evaluation_id]
    assert recover(runtime) == []  # now it is in the queue
    assert runtime.huey.pending_count() == 1


def test_watchdog_finds_a_job_queued_just_before_a_queue_outage(
    runtime: Runtime, evaluation_id: str, monkeypatch
):
    """A job queued just before an outage whose message was lost is queued again ~2 s later.

    The first look after the fault leaves rows younger than 2 s to their message on its way;
    the follow-up look covers them. (Before: the next look was 30 s away, which is what CI's
    Redis-restart fault test measured: the last job finished 30.6 s after the restart.)
    """
    from service.jobs import tracking, watchdog

    clock = {"mono": 1000.0, "wall": utcnow()}
    with runtime.sessions() as session:  # queued now; its message is not in the queue
        session.get_one(Evaluation, evaluation_id).created_at = clock["wall"]
        session.commit()
    monkeypatch.setattr(watchdog.time, "monotonic", lambda: clock["mono"])
    monkeypatch.setattr(tracking, "utcnow", lambda: clock["wall"])
    dog = watchdog.Watchdog(runtime)
    sessions = runtime.sessions

    def unreachable() -> Session:
        statement = "SELECT 1"
        raise OperationalError(statement, {}, ConnectionError("the database is away"))

    monkeypatch.setattr(runtime, "sessions", unreachable)
    assert dog.check() == []  # the outage: logged, nothing done
    monkeypatch.setattr(runtime, "sessions", sessions)

    def tick(seconds: float) -> list[str]:
        clock["mono"] += seconds
        clock["wall"] += dt.timedelta(seconds=seconds)
        return dog.check()

    assert tick(1.0) == []  # back 1 s later; the row is 1 s old, so fresh: left alone
    assert tick(dog.interval) == [evaluation_id]  # 2 s on: found lost, queued again
    assert runtime.huey.pending_count() == 1
    assert tick(dog.interval) == []  # settled: back to the 30 s looks, nothing queued twice
    assert dog._settle_at is None


def test_release_requeues_the_jobs_of_a_stopping_worker(runtime: Runtime, evaluation_id: str):
    """Jobs still running when the service stops are queued again at once, not left running."""
    with runtime.sessions() as session:
        row = session.get_one(Evaluation, evaluation_id)
        row.status, row.worker, row.attempts = "running", runtime.worker_id, 1
        session.commit()
    assert release(runtime) == 1
    row = _row(runtime, evaluation_id)
    assert (row.status, row.worker) == ("queued", None)
    assert [t.args for t in runtime.huey.pending()] == [(evaluation_id,)]


def test_release_leaves_other_workers_jobs(runtime: Runtime, evaluation_id: str):
    """Only this process's jobs are released; another worker's run on."""
    _abandon(runtime, evaluation_id, attempts=1, beat_age_s=0)
    assert release(runtime) == 0
    assert _row(runtime, evaluation_id).status == "running"


def _running_run(rt: Runtime, *, worker: str, attempts: int, beat_age_s: float) -> str:
    """A schedule run left running (the same job columns as an evaluation)."""
    return add_schedule_run(
        rt,
        project_name=f"runs-{worker}",
        trigger="cron",
        status="running",
        worker=worker,
        attempts=attempts,
        heartbeat_at=utcnow() - dt.timedelta(seconds=beat_age_s),
    )


def test_recover_handles_schedule_runs_like_evaluations(runtime: Runtime):
    """An abandoned schedule run is queued again, and failed at the attempt limit."""
    again = _running_run(runtime, worker="dead:1", attempts=1, beat_age_s=120)
    given_up = _running_run(runtime, worker="dead:2", attempts=3, beat_age_s=120)
    recover(runtime)
    with runtime.sessions() as session:
        assert session.get_one(ScheduleRun, again).status == "queued"
        failed = session.get_one(ScheduleRun, given_up)
    assert failed.status == "failed"
    assert failed.error is not None
    assert failed.error["type"] == "run.interrupted"
    assert [t.args for t in runtime.huey.pending()] == [(again,)]


def test_release_requeues_this_workers_schedule_runs(runtime: Runtime):
    """A stopping service queues its unfinished schedule runs again too."""
    run_id = _running_run(runtime, worker=runtime.worker_id, attempts=1, beat_age_s=0)
    assert release(runtime) == 1
    with runtime.sessions() as session:
        assert session.get_one(ScheduleRun, run_id).status == "queued"
