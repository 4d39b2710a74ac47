"""Retention: DELETE /evaluations/{id}, the hourly sweep, and the 507 of a nearly full disk."""

from __future__ import annotations

import datetime as dt
import errno
import logging
import os
import time
from collections import namedtuple
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import anyio
import numpy as np
import pytest
from pydantic import ValidationError
from starlette.requests import Request

from service.api.multipart import receive_multipart
from service.blobs.local import LocalBlobs
from service.cli import main
from service.db import Evaluation, JobStatus, Schedule, ScheduleRun, new_id, utcnow
from service.errors import InsufficientStorageError
from service.jobs.retention import sweep
from service.runtime import Runtime
from service.settings import Settings
from tests.service._api_fixtures import (
    Api,
    assert_no_server_paths,
    assert_problem,
    open_api,
    tum_pair,
)

CHEAP = {"formats": ["result.json", "errors.csv"]}
NOW = dt.datetime(2026, 11, 23, 12, 0, tzinfo=dt.UTC)
_Usage = namedtuple("_Usage", ["total", "used", "free"])  # noqa: PYI024  (shutil's shape)


@pytest.fixture
def api(tmp_path: Path) -> Iterator[Api]:
    """A fresh app (immediate jobs), evaluations kept for 30 days."""
    with open_api(tmp_path, retention_days=30) as api:
        yield api


def runtime_of(api: Api) -> Runtime:
    """Return the app's runtime."""
    runtime: Runtime = api.app.state.runtime
    return runtime


def evaluate(api: Api, rng: np.random.Generator, tmp_path: Path) -> dict[str, Any]:
    """Upload a TUM pair and run one evaluation to its end; return it."""
    reference, estimate = tum_pair(rng, tmp_path)
    body = {
        "reference": {"dataset_id": api.dataset("truth.txt", reference)["id"]},
        "estimates": [{"dataset_id": api.dataset("slam.txt", estimate)["id"]}],
        "options": CHEAP,
    }
    response = api.client.post("/api/v1/evaluations", headers=api.headers, json=body)
    assert response.status_code == 202, response.text
    done = api.client.get(f"/api/v1/evaluations/{response.json()['id']}", headers=api.headers)
    assert done.json()["status"] == "succeeded", done.text
    evaluation: dict[str, Any] = done.json()
    return evaluation


def insert(
    api: Api,
    *,
    status: str,
    finished_at: dt.datetime | None,
    created_at: dt.datetime = NOW,
    project_id: str | None = None,
) -> str:
    """Record an evaluation row with a file in its artifacts folder; return its id."""
    evaluation = Evaluation(
        project_id=project_id or api.project_id(),
        status=status,
        stage=status,
        request={"reference": {"dataset_id": "x"}, "estimates": [], "options": {}},
        dataset_ids=[],
        created_at=created_at,
        finished_at=finished_at,
    )
    with runtime_of(api).sessions() as session:
        session.add(evaluation)
        session.commit()
    folder = runtime_of(api).store.artifacts_dir(evaluation.id)
    folder.mkdir(parents=True)
    (folder / "result.json").write_text("{}")
    return evaluation.id


def remaining(api: Api) -> set[str]:
    """Return the ids of every evaluation row."""
    from sqlalchemy import select

    with runtime_of(api).sessions() as session:
        return set(session.scalars(select(Evaluation.id)))


def job_folder(api: Api, evaluation_id: str) -> Path:
    """Return an evaluation's folder in the data directory."""
    return api.data_dir / "evaluations" / evaluation_id


# --- DELETE /evaluations/{id} -----------------------------------------------------------


def test_delete_removes_row_and_artifacts(
    api: Api, rng: np.random.Generator, tmp_path: Path
) -> None:
    """204 with no body; the evaluation answers 404 after; its folder is gone, datasets stay."""
    evaluation = evaluate(api, rng, tmp_path)
    folder = job_folder(api, evaluation["id"])
    assert (folder / "artifacts" / "errors.csv").is_file()
    response = api.client.delete(f"/api/v1/evaluations/{evaluation['id']}", headers=api.headers)
    assert response.status_code == 204
    assert response.content == b""
    assert not folder.exists()
    assert evaluation["id"] not in remaining(api)
    url = f"/api/v1/evaluations/{evaluation['id']}"
    assert_problem(api.client.get(url, headers=api.headers), 404, type_="not_found")
    assert_problem(
        api.client.get(f"{url}/artifacts/errors.csv", headers=api.headers), 404, type_="not_found"
    )
    listed = api.client.get("/api/v1/datasets", headers=api.headers).json()
    assert listed["count"] == 2  # the recordings are not the evaluation's to delete
    again = api.client.delete(url, headers=api.headers)
    assert_problem(again, 404, detail="list them with GET /evaluations")


def test_delete_failed_evaluation(api: Api) -> None:
    """A failed evaluation is finished too: deleted with its folder."""
    failed = insert(api, status=JobStatus.FAILED, finished_at=utcnow())
    response = api.client.delete(f"/api/v1/evaluations/{failed}", headers=api.headers)
    assert response.status_code == 204
    assert not job_folder(api, failed).exists()
    assert failed not in remaining(api)


@pytest.mark.parametrize("status", [JobStatus.QUEUED, JobStatus.RUNNING])
def test_delete_unfinished_is_409(api: Api, status: str) -> None:
    """A queued or running evaluation is refused with what to do; nothing is removed."""
    active = insert(api, status=status, finished_at=None)
    response = api.client.delete(f"/api/v1/evaluations/{active}", headers=api.headers)
    body = assert_problem(response, 409, type_="conflict", detail=f"is {status}")
    assert "delete it once it has succeeded or failed" in body["detail"]
    assert active in remaining(api)
    assert (job_folder(api, active) / "artifacts" / "result.json").is_file()


def test_delete_unknown_and_other_projects_are_404(api: Api) -> None:
    """An unknown id and another project's evaluation look the same: 404, nothing removed."""
    unknown = api.client.delete(f"/api/v1/evaluations/{new_id()}", headers=api.headers)
    assert_problem(unknown, 404, type_="not_found", detail="No evaluation")
    theirs = insert(api, status=JobStatus.SUCCEEDED, finished_at=utcnow())
    response = api.client.delete(f"/api/v1/evaluations/{theirs}", headers=api.other_headers)
    assert_problem(response, 404, type_="not_found", detail="No evaluation")
    assert theirs in remaining(api)
    assert job_folder(api, theirs).is_dir()


def test_delete_needs_a_key(api: Api) -> None:
    """Without a key: 401 problem, the evaluation stays."""
    kept = insert(api, status=JobStatus.SUCCEEDED, finished_at=utcnow())
    response = api.client.delete(f"/api/v1/evaluations/{kept}")
    assert_problem(response, 401)
    assert kept in remaining(api)


def add_run(api: Api, rows: list[dict[str, Any]]) -> str:
    """Record a finished schedule run with these recording rows; return its id."""
    project_id = api.project_id()
    schedule = Schedule(
        project_id=project_id,
        name="nightly",
        cron="0 3 * * *",
        timezone="UTC",
        selection={},
        template={},
        produce={},
    )
    with runtime_of(api).sessions() as session:
        session.add(schedule)
        session.flush()
        run = ScheduleRun(
            schedule_id=schedule.id,
            project_id=project_id,
            trigger="cron",
            due_at=NOW,
            status=JobStatus.SUCCEEDED,
            rows=rows,
        )
        session.add(run)
        session.commit()
        return run.id


def run_rows(api: Api, run_id: str) -> list[dict[str, Any]]:
    """Return a schedule run's recording rows as stored."""
    with runtime_of(api).sessions() as session:
        rows: list[dict[str, Any]] = session.get_one(ScheduleRun, run_id).rows or []
        return rows


def test_schedule_run_marks_its_deleted_evaluation(api: Api) -> None:
    """The run keeps its figures; the row of the deleted evaluation says it was deleted."""
    gone = insert(api, status=JobStatus.SUCCEEDED, finished_at=utcnow())
    kept = insert(api, status=JobStatus.SUCCEEDED, finished_at=utcnow())
    summary = [{"name": "slam", "ate_rmse_m": 0.04}]
    run_id = add_run(
        api,
        [
            {"dataset": "a", "evaluation_id": gone, "status": "succeeded", "summary": summary},
            {"dataset": "b", "evaluation_id": kept, "status": "succeeded", "summary": summary},
            {"dataset": "c", "evaluation_id": None, "status": "failed", "error": "no topic"},
        ],
    )
    response = api.client.delete(f"/api/v1/evaluations/{gone}", headers=api.headers)
    assert response.status_code == 204
    rows = run_rows(api, run_id)
    assert rows[0] == {
        "dataset": "a",
        "evaluation_id": gone,
        "status": "succeeded",
        "summary": summary,
        "evaluation_deleted": True,
    }
    assert "evaluation_deleted" not in rows[1]
    assert "evaluation_deleted" not in rows[2]


# --- the sweep ----------------------------------------------------------------------------


def test_sweep_deletes_finished_evaluations_past_retention(
    api: Api, caplog: pytest.LogCaptureFixture
) -> None:
    """Finished before the cutoff: rows and folders go; newer or unfinished ones stay."""
    days = dt.timedelta(days=1)
    old_ok = insert(api, status=JobStatus.SUCCEEDED, finished_at=NOW - 31 * days)
    old_failed = insert(api, status=JobStatus.FAILED, finished_at=NOW - 45 * days)
    legacy = insert(  # finished without a finish time: its creation time counts
        api, status=JobStatus.FAILED, finished_at=None, created_at=NOW - 40 * days
    )
    recent = insert(api, status=JobStatus.SUCCEEDED, finished_at=NOW - 29 * days)
    old_running = insert(
        api, status=JobStatus.RUNNING, finished_at=None, created_at=NOW - 60 * days
    )
    old_queued = insert(api, status=JobStatus.QUEUED, finished_at=None, created_at=NOW - 60 * days)
    theirs = insert(
        api,
        status=JobStatus.SUCCEEDED,
        finished_at=NOW - 90 * days,
        project_id=api.project_id(api.other_key),
    )
    run_id = add_run(api, [{"dataset": "a", "evaluation_id": old_ok, "status": "succeeded"}])
    with caplog.at_level(logging.INFO, logger="service.jobs.retention"):
        counts = sweep(runtime_of(api), now=NOW)
    assert counts.evaluations == 4
    assert remaining(api) == {recent, old_running, old_queued}
    for gone in (old_ok, old_failed, legacy, theirs):
        assert not job_folder(api, gone).exists()
    for kept in (recent, old_running, old_queued):
        assert (job_folder(api, kept) / "artifacts" / "result.json").is_file()
    assert run_rows(api, run_id)[0]["evaluation_deleted"] is True
    lines = [r for r in caplog.records if getattr(r, "event", None) == "retention_sweep"]
    assert len(lines) == 1
    assert "4 evaluations finished before 2026-10-24 12:00 UTC" in lines[0].getMessage()
    assert sweep(runtime_of(api), now=NOW).evaluations == 0  # idempotent


def test_sweep_deletes_in_batches(api: Api, monkeypatch: pytest.MonkeyPatch) -> None:
    """More expired evaluations than one batch: all go."""
    monkeypatch.setattr("service.jobs.retention._BATCH", 3)
    old = [
        insert(api, status=JobStatus.SUCCEEDED, finished_at=NOW - dt.timedelta(days=100))
        for _ in range(7)
    ]
    assert sweep(runtime_of(api), now=NOW).evaluations == len(old)
    assert remaining(api) == set()


def test_no_retention_keeps_everything(tmp_path: Path) -> None:
    """retention_days=0 (the default) deletes no evaluation, however old."""
    with open_api(tmp_path) as api:
        ancient = insert(api, status=JobStatus.SUCCEEDED, finished_at=NOW - dt.timedelta(days=3000))
        counts = sweep(runtime_of(api), now=NOW)
        assert counts.evaluations == 0
        assert remaining(api) == {ancient}
        assert job_folder(api, ancient).is_dir()


def age(path: Path, seconds: float) -> None:
    """Set a file's or folder's times ``seconds`` into the past."""
    then = time.time() - seconds
    os.utime(path, (then, then))


def test_sweep_removes_old_orphans_only(api: Api) -> None:
    """Job folders without a row go once they are an hour old; datasets' folders never do."""
    store = runtime_of(api).store
    kept = insert(api, status=JobStatus.SUCCEEDED, finished_at=utcnow())
    age(job_folder(api, kept), 7200)
    orphan = store.job_artifacts_dir("evaluations", new_id())
    orphan.mkdir(parents=True)
    (orphan / "report.pdf").write_bytes(b"%PDF")
    age(orphan.parent, 7200)
    young = store.job_folder("evaluations", new_id())
    young.mkdir()
    run_orphan = store.job_folder("runs", new_id())
    run_orphan.mkdir()
    age(run_orphan, 7200)
    not_an_id = store.root / "evaluations" / "notes"
    not_an_id.mkdir()
    age(not_an_id, 7200)
    dataset_orphan = store.datasets / new_id()
    dataset_orphan.mkdir()
    age(dataset_orphan, 7200)
    partial = store.new_incoming()
    partial.write_bytes(b"half")
    age(partial, 7200)
    counts = sweep(runtime_of(api), now=NOW)
    assert (counts.orphans, counts.partial_uploads) == (2, 1)
    assert not orphan.parent.exists()
    assert not run_orphan.exists()
    assert not partial.exists()
    assert young.is_dir()
    assert not_an_id.is_dir()
    assert dataset_orphan.is_dir()
    assert job_folder(api, kept).is_dir()


def test_hourly_task_runs_the_sweep(api: Api) -> None:
    """The queue's periodic task ``retention_sweep`` fires hourly and runs the sweep."""
    huey = runtime_of(api).huey
    at_17 = NOW.replace(hour=10, minute=17, tzinfo=None)  # huey's clock is naive UTC
    assert "retention_sweep" in {t.name for t in huey.read_periodic(at_17)}
    at_18 = at_17.replace(minute=18)
    assert "retention_sweep" not in {t.name for t in huey.read_periodic(at_18)}
    old = insert(api, status=JobStatus.SUCCEEDED, finished_at=utcnow() - dt.timedelta(days=31))
    (task,) = [t for t in huey.read_periodic(at_17) if t.name == "retention_sweep"]
    huey.execute(task)
    assert old not in remaining(api)


@pytest.mark.parametrize("value", [-1, 36501])
def test_retention_days_is_bounded(tmp_path: Path, value: int) -> None:
    """Out-of-range retention is refused when the settings are read."""
    with pytest.raises(ValidationError, match="retention_days"):
        Settings(data_dir=tmp_path, retention_days=value)


def test_bad_retention_setting_exits_1(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``loceval worker`` with a bad LOCEVAL_RETENTION_DAYS: exit 1 naming it, no traceback."""
    from service.settings import get_settings

    monkeypatch.setenv("LOCEVAL_DATA_DIR", str(tmp_path / "data"))
    monkeypatch.setenv("LOCEVAL_RETENTION_DAYS", "forever")
    get_settings.cache_clear()
    try:
        assert main(["worker"]) == 1
    finally:
        get_settings.cache_clear()
    err = capsys.readouterr().err
    assert "LOCEVAL_RETENTION_DAYS" in err
    assert "Traceback" not in err


# --- 507: the disk is nearly full ---------------------------------------------------------


def fake_free(monkeypatch: pytest.MonkeyPatch, *frees: int) -> list[int]:
    """Make ``shutil.disk_usage`` report these free sizes in turn (the last one repeats)."""
    calls: list[int] = []

    def disk_usage(_path: object) -> _Usage:
        free = frees[min(len(calls), len(frees) - 1)]
        calls.append(free)
        return _Usage(1 << 40, (1 << 40) - free, free)

    monkeypatch.setattr("service.blobs.local.shutil.disk_usage", disk_usage)
    return calls


def test_upload_refused_when_storage_is_nearly_full(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, rng: np.random.Generator
) -> None:
    """An upload that would leave less than the reserve: 507, nothing stored, no server path."""
    with open_api(tmp_path, min_free_bytes=10_000_000) as api:
        fake_free(monkeypatch, 10_000_500)  # the upload's few kB would eat into the reserve
        response = api.upload("truth.txt", b"0 0 0 0\n" * 200)
        body = assert_problem(response, 507, type_="storage.full", detail="nearly full")
        assert "try again later" in body["detail"]
        assert_no_server_paths(response.text, api.data_dir, tmp_path)
        assert api.stored() == []
        assert api.client.get("/api/v1/datasets", headers=api.headers).json()["count"] == 0
        one_shot = api.client.post(
            "/api/v1/evaluate",
            headers=api.headers,
            files={"reference": ("truth.txt", b"0 0 0 0\n" * 200)},
        )
        assert_problem(one_shot, 507, type_="storage.full")
        assert api.stored() == []
        assert api.evaluation_count() == 0
        fake_free(monkeypatch, 1 << 40)
        accepted = api.upload("truth.txt", tum_pair(rng, tmp_path)[0])
        assert accepted.status_code == 201, accepted.text


def test_reserve_zero_turns_the_check_off(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, rng: np.random.Generator
) -> None:
    """min_free_bytes=0: an upload is accepted however little space is reported."""
    with open_api(tmp_path, min_free_bytes=0) as api:
        calls = fake_free(monkeypatch, 0)
        reference, _ = tum_pair(rng, tmp_path)
        assert api.upload("truth.txt", reference).status_code == 201
        assert calls == []


BOUNDARY = "retention-boundary"


class _Body:
    """An ASGI receive(): the chunks, then the end of the body."""

    def __init__(self, chunks: list[bytes]) -> None:
        self.messages = [{"type": "http.request", "body": c, "more_body": True} for c in chunks]
        self.messages.append({"type": "http.request", "body": b"", "more_body": False})
        self.received = 0

    async def __call__(self) -> dict[str, Any]:
        self.received += 1
        return self.messages.pop(0) if self.messages else {"type": "http.disconnect"}


def multipart(content: bytes) -> bytes:
    """Return a form with one file in the field ``file``."""
    return (
        (
            f'--{BOUNDARY}\r\nContent-Disposition: form-data; name="file"; filename="big.bag"\r\n'
            "Content-Type: application/octet-stream\r\n\r\n"
        ).encode()
        + content
        + f"\r\n--{BOUNDARY}--\r\n".encode()
    )


def receive(store: LocalBlobs, body: _Body, *, length: int | None, min_free: int) -> Any:
    """Run receive_multipart on a synthetic request."""
    headers = [(b"content-type", f"multipart/form-data; boundary={BOUNDARY}".encode())]
    if length is not None:
        headers.append((b"content-length", str(length).encode()))
    scope = {"type": "http", "method": "POST", "path": "/", "headers": headers, "query_string": b""}
    request = Request(scope, body)

    async def go() -> Any:
        return await receive_multipart(
            request,
            store,
            max_bytes=1 << 40,
            file_fields=frozenset({"file"}),
            min_free_bytes=min_free,
        )

    return anyio.run(go)


def incoming(store: LocalBlobs) -> list[Path]:
    """Return the files left in incoming/."""
    return sorted(store.incoming.iterdir())


def test_announced_size_checked_before_reading(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Content-Length larger than free space minus the reserve: 507 before a byte is read."""
    store = LocalBlobs(tmp_path / "data")
    fake_free(monkeypatch, 5_000_000)
    data = multipart(b"x" * 100)
    body = _Body([data])
    with pytest.raises(InsufficientStorageError, match="nearly full"):
        receive(store, body, length=4_500_000, min_free=1_000_000)
    assert body.received == 0
    assert incoming(store) == []


def test_space_running_out_midstream_removes_the_partial_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, rng: np.random.Generator
) -> None:
    """Without Content-Length the free space is checked while receiving; the .part goes."""
    store = LocalBlobs(tmp_path / "data")
    calls = fake_free(monkeypatch, 1 << 40, 1 << 40, 500_000)  # free falls as the file arrives
    content = rng.integers(0, 256, 40 << 20, dtype=np.uint8).tobytes()
    data = multipart(content)
    chunks = [data[i : i + (1 << 20)] for i in range(0, len(data), 1 << 20)]
    with pytest.raises(InsufficientStorageError):
        receive(store, _Body(chunks), length=None, min_free=1_000_000)
    assert len(calls) == 3  # before, at the first byte, after 16 MB: refused there
    assert incoming(store) == []


def test_disk_full_on_write_is_507_and_leaves_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A write that fails with ENOSPC (space taken by someone else): 507, no .part left."""
    store = LocalBlobs(tmp_path / "data")

    def full(_fd: int) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr("service.blobs.local.os.fsync", full)
    with pytest.raises(InsufficientStorageError, match="nearly full"):
        receive(store, _Body([multipart(b"0 0 0 0\n")]), length=None, min_free=0)
    assert incoming(store) == []
