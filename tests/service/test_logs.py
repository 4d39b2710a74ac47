"""Logging: JSON lines off a terminal, one line per request and per job transition."""

from __future__ import annotations

import io
import json
import logging
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from service.logs import configure_logging, log_context
from tests import bagfactory as bf
from tests.factories import make_trajectory, perturb, write_tum
from tests.service._api_fixtures import open_api
from tests.service.conftest import running_server, submit, upload, wait_for_evaluation

_ACCESS_LINE = re.compile(r'"(GET|POST) /\S* HTTP/1\.1" \d{3}')


class _Terminal(io.StringIO):
    """A text stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def _json_lines(text: str) -> list[dict[str, Any]]:
    """Return the JSON objects among the lines of ``text`` (other lines are skipped)."""
    return [json.loads(line) for line in text.splitlines() if line.startswith("{")]


def test_json_lines_carry_the_context_and_the_extra_fields() -> None:
    """Off a terminal each line is one JSON object with its context and extra fields."""
    stream = io.StringIO()
    configure_logging(stream=stream)
    with log_context(request_id="r-1", project=None), log_context(job_id="j-1"):
        logging.getLogger("service.test").info("hello %s", "site", extra={"event": "demo"})
    logging.getLogger("service.test").warning("after")
    first, second = _json_lines(stream.getvalue())
    assert first["message"] == "hello site"
    assert (first["level"], first["logger"], first["event"]) == ("info", "service.test", "demo")
    assert (first["request_id"], first["job_id"]) == ("r-1", "j-1")
    assert "project" not in first  # None values are left out of the context
    assert "request_id" not in second  # the context ends with its block


def test_a_terminal_gets_readable_lines() -> None:
    """On a terminal a line reads as text, its fields as key=value."""
    stream = _Terminal()
    configure_logging(stream=stream)
    with log_context(job_id="j-2"):
        logging.getLogger("service.test").info("started", extra={"attempt": 1})
    (line,) = stream.getvalue().splitlines()
    assert not line.startswith("{")
    assert re.search(r" INFO +service\.test: started  job_id=j-2 attempt=1$", line), line


def test_configuring_again_replaces_the_handler_and_takes_over_uvicorn() -> None:
    """A second call leaves one handler; uvicorn's own handlers are removed, its lines routed."""
    stale = logging.StreamHandler(io.StringIO())
    logging.getLogger("uvicorn.error").addHandler(stale)  # as uvicorn's dictConfig does
    configure_logging(stream=io.StringIO())
    stream = io.StringIO()
    configure_logging(stream=stream)
    logging.getLogger("uvicorn.error").info("Uvicorn running on http://127.0.0.1:1")
    assert stale not in logging.getLogger("uvicorn.error").handlers
    (line,) = _json_lines(stream.getvalue())
    assert (line["logger"], line["message"]) == (
        "uvicorn.error",
        "Uvicorn running on http://127.0.0.1:1",
    )


def _tum_pair(tmp_path: Path, rng: Any) -> tuple[Path, Path]:
    """Write a ground truth and a noisy estimate of it (different bytes: two datasets)."""
    truth = make_trajectory(rng, 120)
    return (
        write_tum(tmp_path / "gt.txt", truth),
        write_tum(tmp_path / "est.txt", perturb(truth, rng)),
    )


def test_the_app_logs_each_request_and_each_job_transition(tmp_path: Path, rng, capsys) -> None:
    """A request is one line with its id; the job it queues logs queued/started/succeeded."""
    gt, est = _tum_pair(tmp_path, rng)
    with open_api(tmp_path) as api:
        capsys.readouterr()
        reference = api.dataset("gt.txt", gt.read_bytes())
        estimate = api.dataset("est.txt", est.read_bytes())
        body = {
            "reference": {"dataset_id": reference["id"]},
            "estimates": [{"dataset_id": estimate["id"]}],
            "options": {"formats": ["result.json"]},
        }
        answer = api.client.post(
            "/api/v1/evaluations", json=body, headers={**api.headers, "X-Request-ID": "req-42"}
        )
        project = api.project_id()
    assert answer.status_code == 202, answer.text
    assert answer.headers["x-request-id"] == "req-42"
    lines = _json_lines(capsys.readouterr().err)
    requests = [line for line in lines if line.get("event") == "request"]
    assert [(r["method"], r["path"], r["status"]) for r in requests] == [
        ("POST", "/api/v1/datasets", 201),
        ("POST", "/api/v1/datasets", 201),
        ("POST", "/api/v1/evaluations", 202),
    ]
    assert requests[2]["request_id"] == "req-42"
    assert requests[2]["project"] == project
    assert all(r["duration_ms"] > 0 for r in requests)
    assert len({r["request_id"] for r in requests}) == 3
    job = [line for line in lines if line.get("kind") == "evaluation" and "event" in line]
    assert [j["event"] for j in job] == ["queued", "started", "succeeded"]
    assert {j["job_id"] for j in job} == {answer.json()["id"]}
    assert all(j["request_id"] == "req-42" for j in job)  # immediate mode: inside the request
    started, succeeded = job[1], job[2]
    assert (started["project"], started["attempt"]) == (project, 1)
    assert (succeeded["project"], succeeded["attempt"]) == (project, 1)
    assert succeeded["duration_s"] > 0
    assert "error" not in succeeded  # fields without a value are left out


def test_a_failed_job_logs_its_problem_type(tmp_path: Path, rng, capsys) -> None:
    """A job that fails on its input logs ``failed`` with the problem type, at warning."""
    truth = make_trajectory(rng, 120)
    gt = write_tum(tmp_path / "gt.txt", truth).read_bytes()
    later = make_trajectory(rng, 120, t0_ns=int(truth.stamps_ns[-1]) + 10**12)
    est = write_tum(tmp_path / "late.txt", later).read_bytes()
    with open_api(tmp_path) as api:
        reference = api.dataset("gt.txt", gt)
        estimate = api.dataset("late.txt", est)
        capsys.readouterr()
        answer = api.evaluate(
            {
                "reference": {"dataset_id": reference["id"]},
                "estimates": [{"dataset_id": estimate["id"]}],
                "options": {"formats": ["result.json"]},
            }
        )
    assert answer.json()["status"] == "failed"
    lines = _json_lines(capsys.readouterr().err)
    (failed,) = [line for line in lines if line.get("event") == "failed"]
    assert failed["level"] == "warning"
    assert failed["error"] == answer.json()["error"]["type"]


@pytest.mark.slow
def test_loceval_serve_logs_requests_and_jobs_as_json(tmp_path: Path, rng) -> None:
    """A real ``loceval serve``: JSON lines for requests, job transitions and uvicorn itself."""
    gt, est = _tum_pair(tmp_path, rng)
    with running_server(tmp_path / "data") as server, server.client() as client:
        reference = upload(client, gt)
        estimate = upload(client, est)
        evaluation = submit(
            client, {"dataset_id": reference["id"]}, [{"dataset_id": estimate["id"]}],
            {"formats": ["result.json"]},
        )  # fmt: skip
        assert wait_for_evaluation(client, evaluation["id"])["status"] == "succeeded"
        server.stop()
        output = server.output
    lines = _json_lines(output)
    requests = [line for line in lines if line.get("event") == "request"]
    posted = [r for r in requests if r["method"] == "POST"]
    assert [(r["path"], r["status"]) for r in posted] == [
        ("/api/v1/datasets", 201),
        ("/api/v1/datasets", 201),
        ("/api/v1/evaluations", 202),
    ]
    assert all(r["request_id"] and r["project"] for r in posted)
    polls = [r for r in requests if r["path"] == f"/api/v1/evaluations/{evaluation['id']}"]
    assert polls
    assert all(r["status"] == 200 for r in polls)
    job = [line for line in lines if line.get("job_id") == evaluation["id"] and "kind" in line]
    events = [j["event"] for j in job if j.get("event")]
    assert events == ["queued", "started", "succeeded"]
    assert job[0]["request_id"] == posted[2]["request_id"]  # queued inside the POST
    assert job[-1]["project"] == posted[2]["project"]
    assert not _ACCESS_LINE.search(output)  # no second access log next to ours
    assert any(
        line["logger"] == "uvicorn.error" and "Uvicorn running" in line["message"] for line in lines
    )


def _bag_with_singular_covariances(tmp_path: Path, rng: Any) -> Path:
    """Write an MCAP bag: ``/gt`` poses and a ``/est`` with covariance, every tenth singular."""
    truth = bf.random_poses(rng, 300, dt_ns=100_000_000)
    noisy = truth.positions + rng.normal(0.0, 0.02, truth.positions.shape)
    estimate = bf.Poses(truth.stamps_ns, noisy, truth.quats)
    records = bf.pose_records("/gt", "geometry_msgs/msg/PoseStamped", truth)
    with_covariance = bf.pose_records("/est", bf.POSE_COV, estimate)
    covariance = np.diag([4e-4] * 3 + [1e-4] * 3).ravel()
    for k, record in enumerate(with_covariance):
        if k % 10:  # the others keep an all-zero (singular) covariance
            record.extra["covariance"] = covariance
    folder = bf.write_bag(bf.bag_path(tmp_path, "mcap"), records + with_covariance, fmt="mcap")
    return folder / "rec.mcap"


@pytest.mark.slow
def test_a_jobs_core_warnings_are_json_lines_with_its_job_id(tmp_path: Path, rng) -> None:
    """Under ``loceval serve`` the core's log lines from the job's own process carry job_id."""
    bag = _bag_with_singular_covariances(tmp_path, rng)
    with running_server(tmp_path / "data") as server, server.client() as client:
        dataset = upload(client, bag)
        evaluation = submit(
            client,
            {"dataset_id": dataset["id"], "selector": "/gt"},
            [{"dataset_id": dataset["id"], "selector": "/est"}],
            {"formats": ["result.json"]},
        )
        assert wait_for_evaluation(client, evaluation["id"])["status"] == "succeeded"
        server.stop()
        output = server.output
    lines = _json_lines(output)
    core = [line for line in lines if line["logger"] == "loceval.assessment.consistency"]
    assert [line["message"] for line in core] == [
        "30 poses with a singular position covariance skipped in NEES",
        "30 poses with a singular rotation covariance skipped in NEES",
    ]
    assert all(line["level"] == "warning" for line in core)
    assert {line["job_id"] for line in core} == {evaluation["id"]}
    assert {line["kind"] for line in core} == {"evaluation"}


@pytest.mark.slow
def test_a_jobs_result_warnings_are_logged_with_its_job_id(tmp_path: Path, rng) -> None:
    """Under ``loceval serve`` each warning of a job's result is a warning line with job_id."""
    gt, est = _tum_pair(tmp_path, rng)
    rows = est.read_text().splitlines()
    est.write_text("\n".join([*rows[:50], rows[49], *rows[50:]]) + "\n")  # a duplicate stamp
    with running_server(tmp_path / "data") as server, server.client() as client:
        reference = upload(client, gt)
        estimate = upload(client, est)
        evaluation = submit(
            client, {"dataset_id": reference["id"]}, [{"dataset_id": estimate["id"]}],
            {"formats": ["result.json"]},
        )  # fmt: skip
        done = wait_for_evaluation(client, evaluation["id"])
        assert done["status"] == "succeeded"
        result = client.get(f"/api/v1/evaluations/{evaluation['id']}").json()["result"]
        server.stop()
        output = server.output
    (warned,) = [w for e in result["estimates"] for w in e["warnings"] if "duplicate" in w]
    lines = _json_lines(output)
    logged = [line for line in lines if line.get("message") == warned]
    assert len(logged) == 1, output
    (line,) = logged
    assert line["level"] == "warning"
    assert line["job_id"] == evaluation["id"]
    assert (line["kind"], line["warning_in"]) == ("evaluation", result["estimates"][0]["name"])
    assert line["project"] == next(
        j["project"] for j in lines if j.get("job_id") == evaluation["id"] and j.get("project")
    )
