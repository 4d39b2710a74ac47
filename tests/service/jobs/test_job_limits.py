"""Every evaluation job runs in a child process with a wall-time and a memory limit.

A job past ``job_timeout_s`` is killed and fails with the reason, and its worker takes the
next job; a job past ``job_memory_mb`` fails with the reason; an error of the core in the
child fails the job exactly as it would in-process; progress crosses the process boundary.
The child runs stand-ins from :mod:`tests.service._job_hooks` (a child imports its work by
name, so tests patch ``service.jobs.executor.run_job`` with those module-level functions).
"""

from __future__ import annotations

import datetime as dt
import logging
import multiprocessing
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pydantic import ValidationError

from loceval.errors import AssociationError, InputError, LocevalError
from service.cli import OUT_OF_MEMORY
from service.cli import main as cli_main
from service.db import Evaluation, Project
from service.errors import problem_for
from service.jobs import executor as jobs
from service.jobs.executor import execute_evaluation
from service.jobs.limits import JobMemoryError, JobProcessError, Limits, run_limited
from service.jobs.queue import create_runtime
from service.jobs.runner import run_job
from service.runtime import Runtime
from service.settings import Settings
from tests.factories import make_trajectory, write_tum
from tests.service import _job_hooks as hooks
from tests.service._api_fixtures import open_api
from tests.service._job_rows import add_dataset

REPO = Path(__file__).resolve().parents[3]
FINISHED = {"succeeded", "failed"}


@pytest.fixture
def files(tmp_path: Path, rng: np.random.Generator) -> tuple[Path, Path]:
    """A TUM reference and an identical estimate (200 poses)."""
    truth = make_trajectory(rng, 200)
    return write_tum(tmp_path / "gt.txt", truth), write_tum(tmp_path / "est.txt", truth)


def _runtime(tmp_path: Path, **settings: Any) -> Runtime:
    """A runtime on SQLite with huey's SQLite queue (nothing consumes it unless started)."""
    return create_runtime(Settings(data_dir=tmp_path / "data", job_lease_s=30, **settings))


@pytest.fixture
def project(files: tuple[Path, Path]) -> Any:
    """Return a function that stores the files in a runtime and queues evaluations of them."""

    def add(rt: Runtime, *, reference_name: str = "truth", **options: Any) -> str:
        with rt.sessions() as session:
            project = session.query(Project).first() or Project(name="site")
            session.add(project)
            session.commit()
            project_id = project.id
        ids = [add_dataset(rt, project_id, path) for path in files]
        with rt.sessions() as session:
            evaluation = Evaluation(
                project_id=project_id,
                request={
                    "reference": {"dataset_id": ids[0], "selector": None, "name": reference_name},
                    "estimates": [{"dataset_id": ids[1], "selector": None, "name": "copy"}],
                    "options": {"formats": ["errors.csv"], **options},
                },
                dataset_ids=ids,
            )
            session.add(evaluation)
            session.commit()
            return evaluation.id

    return add


def _row(rt: Runtime, evaluation_id: str) -> Evaluation:
    with rt.sessions() as session:
        return session.get_one(Evaluation, evaluation_id)


def _wait_finished(rt: Runtime, ids: list[str], timeout_s: float = 120.0) -> list[Evaluation]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        rows = [_row(rt, i) for i in ids]
        if all(r.status in FINISHED for r in rows):
            return rows
        time.sleep(0.2)
    pytest.fail(f"jobs still running after {timeout_s} s: {[r.status for r in rows]}")


def _duration_s(row: Evaluation) -> float:
    assert row.started_at is not None
    assert row.finished_at is not None
    return (row.finished_at - row.started_at) / dt.timedelta(seconds=1)


# --- the wall-time limit ------------------------------------------------------------------


def test_a_job_past_its_time_limit_fails_and_its_worker_takes_the_next(
    tmp_path: Path, project: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """One worker thread: the hanging job is stopped at the limit, then the next one runs."""
    monkeypatch.setattr(jobs, "run_job", hooks.sleep_if_sleeper)
    rt = _runtime(tmp_path, workers=1, job_timeout_s=3)
    hanging = project(rt, reference_name=hooks.SLEEPER)
    normal = project(rt)
    consumer = rt.start_consumer(periodic=False)
    try:
        rt.enqueue("evaluation", hanging)
        rt.enqueue("evaluation", normal)
        stopped, done = _wait_finished(rt, [hanging, normal])
    finally:
        rt.stop_consumer(consumer)
        rt.close()
    assert stopped.status == "failed"
    assert stopped.error is not None
    assert stopped.error["type"] == "job.timeout"
    assert stopped.error["status"] == 422
    assert stopped.error["detail"].startswith(
        "The evaluation was stopped after 3 s (LOCEVAL_JOB_TIMEOUT_S, the longest a job may run);"
    )
    assert "options.rpe_delta" in stopped.error["detail"]  # says what to do
    assert stopped.stage == "searching pairs"  # the child's progress reached the row
    assert 3.0 <= _duration_s(stopped) < 20.0
    # The same single worker ran the next job after the stopped one.
    assert done.status == "succeeded", done.error
    assert [a["name"] for a in done.artifacts or []] == ["result.json", "errors.csv"]
    assert done.worker == stopped.worker == rt.worker_id
    assert done.started_at is not None
    assert stopped.finished_at is not None
    assert done.started_at >= stopped.finished_at
    assert multiprocessing.active_children() == []  # the hanging process is gone


def test_a_hanging_job_over_http_fails_with_the_reason(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, files: tuple[Path, Path]
) -> None:
    """Over the API the job fails with the reason, and the next evaluation succeeds."""
    monkeypatch.setattr(jobs, "run_job", hooks.sleep_if_sleeper)
    with open_api(tmp_path, job_timeout_s=2) as api:
        ref = api.dataset("gt.txt", files[0].read_bytes())["id"]
        est = api.dataset("est.txt", files[1].read_bytes())["id"]

        def body(name: str) -> dict[str, Any]:
            return {
                "reference": {"dataset_id": ref, "name": name},
                "estimates": [{"dataset_id": est}],
                "options": {"formats": ["result.json"]},
            }

        started = time.monotonic()
        response = api.evaluate(body(hooks.SLEEPER))
        assert time.monotonic() - started < 30.0
        assert response.status_code == 202, response.text
        stopped = api.client.get(response.headers["Location"], headers=api.headers).json()
        assert stopped["status"] == "failed"
        assert stopped["error"]["type"] == "job.timeout"
        assert "stopped after 2 s (LOCEVAL_JOB_TIMEOUT_S" in stopped["error"]["detail"]
        following = api.evaluate(body("truth")).json()
        assert following["status"] == "succeeded", following["error"]


# --- the memory limit ---------------------------------------------------------------------


def test_a_job_past_its_memory_limit_fails_with_the_reason(
    tmp_path: Path, project: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A job taking memory without end fails at the limit; the next evaluation succeeds."""
    rt = _runtime(tmp_path, job_memory_mb=1024)
    try:
        greedy = project(rt)
        monkeypatch.setattr(jobs, "run_job", hooks.grow)
        execute_evaluation(rt, greedy)
        failed = _row(rt, greedy)
        monkeypatch.setattr(jobs, "run_job", run_job)
        normal = project(rt)
        execute_evaluation(rt, normal)
        done = _row(rt, normal)
    finally:
        rt.close()
    assert failed.status == "failed"
    assert failed.error is not None
    assert failed.error["type"] == "job.out_of_memory"
    assert failed.error["status"] == 422
    assert failed.error["detail"].startswith(
        "The evaluation needed more than 1024 MiB of memory (LOCEVAL_JOB_MEMORY_MB) and was "
        "stopped; evaluate shorter recordings"
    )
    assert not rt.store.artifacts_dir(greedy).exists()
    assert done.status == "succeeded", done.error
    assert (rt.store.artifacts_dir(normal) / "errors.csv").is_file()


def test_a_process_killed_by_the_system_is_reported_as_out_of_memory() -> None:
    """SIGKILL that the service did not send is the kernel's out-of-memory killer."""
    with pytest.raises(JobMemoryError, match=r"killed by the system \(SIGKILL\)"):
        run_limited(Limits(timeout_s=30, memory_mb=0), hooks.killed)


# --- what else a child can do -------------------------------------------------------------


def test_a_core_error_in_the_child_is_the_same_problem_as_in_process(
    tmp_path: Path, project: Any
) -> None:
    """No overlap in time (a real core error): the stored problem is the in-process one."""
    rt = _runtime(tmp_path)
    try:
        evaluation_id = project(rt, time_offset_s=1000.0)
        with rt.sessions() as session:
            work = jobs._job_for(session, rt, session.get_one(Evaluation, evaluation_id))
        with pytest.raises(AssociationError) as in_process:
            run_job(work, None)
        execute_evaluation(rt, evaluation_id)
        row = _row(rt, evaluation_id)
    finally:
        rt.close()
    assert row.status == "failed"
    assert row.error == problem_for(in_process.value)
    assert row.error["status"] == 422
    assert row.error["type"] == "association.no_matches"


def test_an_error_keeps_its_class_option_and_suggestion() -> None:
    """The error raised in the parent is the child's: class, message, option, suggestion."""
    with pytest.raises(InputError) as caught:
        run_limited(Limits(timeout_s=30, memory_mb=1024), hooks.header_stamps_zero)
    assert str(caught.value) == "Every header stamp is zero."
    assert (caught.value.option, caught.value.suggest) == ("stamp", "receive")
    assert problem_for(caught.value)["detail"] == (
        'options.stamp: Every header stamp is zero. Set options.stamp to "receive".'
    )


def test_progress_reported_in_the_child_is_stored(
    tmp_path: Path, project: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The stage and fraction the child reports are the row's (a failure keeps them)."""
    monkeypatch.setattr(jobs, "run_job", hooks.report_then_fail)
    rt = _runtime(tmp_path)
    try:
        evaluation_id = project(rt)
        execute_evaluation(rt, evaluation_id)
        row = _row(rt, evaluation_id)
    finally:
        rt.close()
    assert (row.status, row.stage, row.fraction) == ("failed", "reading the halfway file", 0.5)
    assert row.error is not None
    assert row.error["detail"] == "The halfway file is unreadable; upload it again."


def test_a_child_that_exits_without_a_result_is_an_internal_error(
    tmp_path: Path, project: Any, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """A child leaving with no outcome is a bug: the job shows an error id, the log the code."""
    monkeypatch.setattr(jobs, "run_job", hooks.exit_quietly)
    rt = _runtime(tmp_path)
    try:
        evaluation_id = project(rt)
        with caplog.at_level(logging.ERROR):
            execute_evaluation(rt, evaluation_id)
        row = _row(rt, evaluation_id)
    finally:
        rt.close()
    assert row.status == "failed"
    assert row.error is not None
    assert row.error["type"] == "internal"
    assert row.error["error_id"] in caplog.text
    assert "exited with code 3 and no result" in caplog.text


def test_a_bug_in_the_child_brings_its_traceback() -> None:
    """Another exception in the child is a JobProcessError with the child's traceback."""
    with pytest.raises(JobProcessError, match=r"(?s)failed:\n.*RuntimeError: boom"):
        run_limited(Limits(timeout_s=30, memory_mb=1024), hooks.crash)


def test_a_child_ends_when_its_parent_dies(tmp_path: Path) -> None:
    """A worker killed hard leaves no job process behind (it would run on without limits)."""
    script = (
        "import sys, time\n"
        "from service.jobs.limits import Limits, run_limited\n"
        "from tests.service import _job_hooks as hooks\n"
        "def show(stage, fraction):\n"
        "    print(stage, flush=True)\n"
        "if __name__ == '__main__':\n"
        "    run_limited(Limits(timeout_s=600, memory_mb=0), hooks.sleep_forever, progress=show)\n"
    )
    (tmp_path / "parent.py").write_text(script)
    parent = subprocess.Popen(
        [sys.executable, str(tmp_path / "parent.py")],
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert parent.stdout is not None
        line = parent.stdout.readline()
        assert line.startswith("pid "), line
        child = int(line.split()[1])
        assert _alive(child)
    finally:
        parent.kill()
        parent.wait(timeout=30)
        if parent.stdout is not None:
            parent.stdout.close()
    deadline = time.monotonic() + 30
    while _alive(child) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _alive(child)


def _alive(pid: int) -> bool:
    """Return whether a process runs (a zombie does not count)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state != "Z"


# --- settings and the command line --------------------------------------------------------


def test_limit_settings_defaults_and_bounds(monkeypatch: pytest.MonkeyPatch) -> None:
    """Defaults: 30 minutes and 4 GiB; 0 turns the memory limit off; nonsense is refused."""
    settings = Settings()
    assert (settings.job_timeout_s, settings.job_memory_mb) == (1800.0, 4096)
    assert Settings(job_memory_mb=0).job_memory_mb == 0
    monkeypatch.setenv("LOCEVAL_JOB_TIMEOUT_S", "90")
    monkeypatch.setenv("LOCEVAL_JOB_MEMORY_MB", "2048")
    assert Limits.from_settings(Settings()) == Limits(90.0, 2048, "evaluation")
    with pytest.raises(ValidationError, match="LOCEVAL_JOB_MEMORY_MB must be 0"):
        Settings(job_memory_mb=512)
    for bad in ({"job_timeout_s": 0}, {"job_timeout_s": -5}, {"job_memory_mb": -1}):
        with pytest.raises(ValidationError):
            Settings(**bad)


def test_cli_out_of_memory_exits_1_with_what_to_do(
    files: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``loceval evaluate`` running out of memory prints one error line and exits 1."""
    import service.cli.evaluate  # the command's module, patched below

    def exhausted(*_args: object, **_kwargs: object) -> None:
        raise MemoryError

    monkeypatch.setattr(service.cli.evaluate, "run_job", exhausted)
    code = cli_main(["evaluate", str(files[0]), str(files[1])])
    err = capsys.readouterr().err
    assert code == 1
    assert "Traceback" not in err
    assert err.strip() == f"loceval: error: {OUT_OF_MEMORY}"
    assert "--rpe-delta" in OUT_OF_MEMORY


def test_the_limits_are_errors_a_client_can_act_on() -> None:
    """Both limit errors are input errors (422) whose messages name the setting."""
    limits = Limits(timeout_s=60, memory_mb=2048)
    for error, setting in (
        (limits.timeout_error(), "LOCEVAL_JOB_TIMEOUT_S"),
        (limits.memory_error(), "LOCEVAL_JOB_MEMORY_MB"),
    ):
        assert isinstance(error, LocevalError)
        assert problem_for(error)["status"] == 422
        assert setting in str(error)
