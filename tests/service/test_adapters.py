"""Queue and database outages become 503 problems through one adapter; bugs stay 500s."""

from __future__ import annotations

import uuid
from pathlib import Path

import pytest
from sqlalchemy import create_engine, select, text

from loceval.errors import InputError
from service.adapters import converted
from service.blobs.local import LocalBlobs
from service.db import Evaluation
from service.errors import ServiceUnavailableError, problem_for
from tests.factories import make_trajectory, write_tum
from tests.service._api_fixtures import open_api
from tests.service.conftest import free_port


def test_an_unreachable_database_is_a_service_unavailable_error(tmp_path: Path) -> None:
    """SQLAlchemy's OperationalError (a database file that cannot be opened) becomes a 503."""
    engine = create_engine(f"sqlite:///{tmp_path}/missing/folder/loceval.db")
    with (
        pytest.raises(
            ServiceUnavailableError,
            match=r"metadata database cannot be reached \(OperationalError\)",
        ),
        converted("database"),
        engine.connect() as connection,
    ):
        connection.execute(text("SELECT 1"))


def test_other_errors_pass_through_the_adapter() -> None:
    """A bug (any other exception) is not turned into an outage."""
    with pytest.raises(ZeroDivisionError, match="division by zero"), converted("queue"):
        _ = 1 / 0


def test_problem_documents_never_show_the_data_folder(tmp_path: Path) -> None:
    """Every problem is scrubbed where it is built: the data folder and id folders go."""
    store = LocalBlobs(tmp_path / "data")
    dataset_id = str(uuid.uuid4())
    err = InputError(f"{store.root}/datasets/{dataset_id}/run.bag has no topic '/odom'.")
    assert problem_for(err)["detail"] == "run.bag has no topic '/odom'."


def _closed_redis() -> str:
    """Return a Redis URL on a loopback port nothing listens on."""
    return f"redis://127.0.0.1:{free_port()}/0"


def test_readiness_is_503_when_the_queue_is_down(tmp_path: Path) -> None:
    """/readyz answers 503 naming the queue and the error class (redis ConnectionError)."""
    with open_api(tmp_path, queue_url=_closed_redis()) as api:
        answer = api.client.get("/readyz")
    assert answer.status_code == 503
    assert answer.json()["type"] == "service.unavailable"
    assert answer.json()["detail"].startswith(
        "The job queue cannot be reached (ConnectionError); try again in a minute"
    )


def test_a_bug_in_readiness_is_a_500_not_a_503(tmp_path: Path, monkeypatch) -> None:
    """An unexpected exception while checking is a bug: 500 with an error id."""
    with open_api(tmp_path, raise_server_exceptions=False) as api:

        def broken() -> int:
            msg = "a bug"
            raise KeyError(msg)

        monkeypatch.setattr(api.app.state.runtime.huey, "pending_count", broken)
        answer = api.client.get("/readyz")
    assert answer.status_code == 500
    assert answer.json()["type"] == "internal"
    assert answer.json()["error_id"] in answer.json()["detail"]


def test_an_unreachable_queue_fails_the_new_evaluation_with_503(tmp_path: Path, rng) -> None:
    """POST /evaluations with the queue down: 503, and the recorded evaluation is failed."""
    truth = make_trajectory(rng, 50)
    gt = write_tum(tmp_path / "gt.txt", truth).read_bytes()
    with open_api(tmp_path, queue_url=_closed_redis()) as api:
        dataset = api.dataset("gt.txt", gt)
        answer = api.evaluate(
            {
                "reference": {"dataset_id": dataset["id"]},
                "estimates": [{"dataset_id": dataset["id"]}],
            }
        )
        with api.app.state.runtime.sessions() as session:
            (row,) = session.scalars(select(Evaluation)).all()
    assert answer.status_code == 503
    assert answer.json()["type"] == "service.unavailable"
    assert "job queue cannot be reached (ConnectionError)" in answer.json()["detail"]
    assert (row.status, row.stage) == ("failed", "failed")
    assert row.error is not None
    assert row.error["type"] == "service.unavailable"
    assert row.error["detail"] == "The job queue could not be reached; start the evaluation again."
