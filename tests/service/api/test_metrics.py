"""``GET /metrics``: Prometheus' text format, no key, route templates, no names or ids."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from prometheus_client.metrics_core import Metric
from prometheus_client.parser import text_string_to_metric_families
from sqlalchemy.exc import OperationalError

from service.api import metrics as metrics_module
from service.api.metrics import JOB_BUCKETS_S, UNMATCHED
from tests.service._api_fixtures import Api, open_api, tum_pair
from tests.service.conftest import (
    running_server,
    start_worker,
    submit,
    upload,
    wait_for_evaluation,
)

CHEAP = {"formats": ["result.json"]}
CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"
UNKNOWN_ID = "0b7c5cf0-1111-4222-8333-feedfacecafe"


@pytest.fixture
def tum(rng: np.random.Generator, tmp_path: Path) -> tuple[bytes, bytes]:
    """A TUM reference and a noisy TUM estimate of it."""
    return tum_pair(rng, tmp_path)


def scrape(client: Any) -> tuple[str, dict[str, Metric]]:
    """GET /metrics without a key; return the body and its families by name."""
    response = client.get("/metrics")
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == CONTENT_TYPE
    families = {family.name: family for family in text_string_to_metric_families(response.text)}
    return response.text, families


def value(families: dict[str, Metric], sample: str, **labels: str) -> float:
    """Return the value of the one sample ``sample`` with exactly ``labels`` (0 if absent)."""
    family = families[re.sub(r"_(total|bucket|count|sum)$", "", sample)]
    found = [s.value for s in family.samples if s.name == sample and s.labels == labels]
    assert len(found) <= 1, found
    return found[0] if found else 0.0


def buckets(families: dict[str, Metric], name: str, **labels: str) -> list[float]:
    """Return a histogram's cumulative bucket counts, ``+Inf`` last."""
    return [
        s.value
        for s in families[name].samples
        if s.name == f"{name}_bucket" and {k: v for k, v in s.labels.items() if k != "le"} == labels
    ]


def evaluate(api: Api, reference: str, estimate: str, **options: Any) -> dict[str, Any]:
    """POST an evaluation (it runs inside the request); return it."""
    body = {
        "reference": {"dataset_id": reference},
        "estimates": [{"dataset_id": estimate, "name": "secret-slam-system"}],
        "options": {**CHEAP, **options},
    }
    response = api.evaluate(body)
    assert response.status_code == 202, response.text
    evaluation: dict[str, Any] = response.json()
    return evaluation


def test_metrics_count_requests_jobs_and_uploads_without_names(
    api: Api, tum: tuple[bytes, bytes]
) -> None:
    """Counters rise with route templates as labels; jobs and durations come from the rows."""
    _, before = scrape(api.client)
    assert value(before, "loceval_upload_bytes_total") == 0.0
    assert value(before, "loceval_jobs", kind="evaluation", state="succeeded") == 0.0
    reference = api.dataset("truth-level2.txt", tum[0], name="level2-secret-walk", tags="site7")
    estimate = api.dataset("slam-level2.txt", tum[1])
    again = api.dataset("truth-level2.txt", tum[0])  # the same bytes: 200, counted as received
    assert again["id"] == reference["id"]
    passed = evaluate(api, reference["id"], estimate["id"])
    failed = evaluate(api, reference["id"], estimate["id"], time_offset_s=1000.0)
    assert (passed["status"], failed["status"]) == ("succeeded", "failed")
    unknown = api.client.get(f"/api/v1/evaluations/{UNKNOWN_ID}", headers=api.headers)
    assert unknown.status_code == 404
    assert api.client.get("/api/v1/datasets").status_code == 401  # no key
    assert api.client.get(f"/api/v1/nothing/{UNKNOWN_ID}").status_code == 404

    text, families = scrape(api.client)

    def requests(method: str, route: str, status: str) -> float:
        labels = {"method": method, "route": route, "status": status}
        return value(families, "loceval_http_requests_total", **labels)

    assert requests("POST", "/api/v1/datasets", "201") == 2
    assert requests("POST", "/api/v1/datasets", "200") == 1
    assert requests("POST", "/api/v1/evaluations", "202") == 2
    assert requests("GET", "/api/v1/evaluations/{evaluation_id}", "404") == 1
    assert requests("GET", "/api/v1/datasets", "401") == 1
    assert requests("GET", UNMATCHED, "404") == 1
    assert requests("GET", "/metrics", "200") == 1  # the first scrape
    latency = buckets(families, "loceval_http_request_duration_seconds", route="/api/v1/datasets")
    assert latency[-1] == 4  # three uploads and the 401
    assert latency == sorted(latency)
    assert value(families, "loceval_upload_bytes_total") == 2 * len(tum[0]) + len(tum[1])

    jobs = {
        s.labels["state"]: s.value
        for s in families["loceval_jobs"].samples
        if s.labels["kind"] == "evaluation"
    }
    assert jobs == {"queued": 0, "running": 0, "succeeded": 1, "failed": 1}
    assert value(families, "loceval_jobs", kind="run", state="queued") == 0
    for outcome in ("succeeded", "failed"):
        labels = {"kind": "evaluation", "outcome": outcome}
        counts = buckets(families, "loceval_job_duration_seconds", **labels)
        assert len(counts) == len(JOB_BUCKETS_S) + 1
        assert counts == sorted(counts)
        assert counts[-1] == 1
        assert value(families, "loceval_job_duration_seconds_count", **labels) == 1
        assert 0 < value(families, "loceval_job_duration_seconds_sum", **labels) < 60
    assert value(families, "loceval_queue_depth") == 0  # the immediate queue holds nothing
    assert value(families, "loceval_backend_up", backend="database") == 1
    assert value(families, "loceval_backend_up", backend="queue") == 1

    secrets = [
        "site-a",
        "site-b",
        api.project_id(),
        api.project_id(api.other_key),
        api.key,
        reference["id"],
        estimate["id"],
        passed["id"],
        failed["id"],
        UNKNOWN_ID,
        "level2",
        "site7",
        "secret",
        "truth",
    ]
    for secret in secrets:
        assert secret not in text, secret


def test_one_shot_upload_counts_its_files(api: Api, tum: tuple[bytes, bytes]) -> None:
    """POST /evaluate adds the bytes of its reference and estimate files."""
    response = api.client.post(
        "/api/v1/evaluate",
        headers=api.headers,
        files=[("reference", ("gt.txt", tum[0])), ("estimate", ("est.txt", tum[1]))],
        data={"options": json.dumps(CHEAP)},
    )
    assert response.status_code == 202, response.text
    refused = api.client.post(
        "/api/v1/datasets", headers=api.headers, files={"file": ("x.bin", b"\x00garbage")}
    )
    assert refused.status_code in {400, 422}  # not a recording: not counted
    _, families = scrape(api.client)
    assert value(families, "loceval_upload_bytes_total") == len(tum[0]) + len(tum[1])
    labels = {"method": "POST", "route": "/api/v1/evaluate", "status": "202"}
    assert value(families, "loceval_http_requests_total", **labels) == 1
    assert value(families, "loceval_jobs", kind="evaluation", state="succeeded") == 1


def test_each_app_counts_in_its_own_registry(tmp_path: Path) -> None:
    """Two apps in one process: no clash at creation, and neither sees the other's requests."""
    with open_api(tmp_path / "a") as first, open_api(tmp_path / "b") as second:
        for _ in range(3):
            assert first.client.get("/healthz").status_code == 200
        assert second.client.get("/healthz").status_code == 200
        labels = {"method": "GET", "route": "/healthz", "status": "200"}
        _, one = scrape(first.client)
        _, two = scrape(second.client)
    assert value(one, "loceval_http_requests_total", **labels) == 3
    assert value(two, "loceval_http_requests_total", **labels) == 1


def test_backend_outage_answers_with_up_zero(api: Api, monkeypatch: pytest.MonkeyPatch) -> None:
    """A database or queue that cannot be read is reported as down; the scrape still answers."""
    runtime = api.app.state.runtime

    def unreachable(*_args: Any, **_kwargs: Any) -> Any:
        statement = "SELECT 1"
        raise OperationalError(statement, {}, ConnectionError(statement))

    def queue_down() -> int:
        msg = "queue refused"
        raise ConnectionError(msg)

    monkeypatch.setattr(runtime, "sessions", unreachable)
    monkeypatch.setattr(runtime.huey, "pending_count", queue_down)
    _, families = scrape(api.client)
    assert value(families, "loceval_backend_up", backend="database") == 0
    assert value(families, "loceval_backend_up", backend="queue") == 0
    assert "loceval_jobs" not in families
    assert "loceval_queue_depth" not in families
    assert "loceval_http_requests" in families


def test_durations_read_without_sql_arithmetic_agree(
    api: Api, tum: tuple[bytes, bytes], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A database without a known duration expression gets the same histogram, counted here."""
    reference = api.dataset("a.txt", tum[0])["id"]
    estimate = api.dataset("b.txt", tum[1])["id"]
    for offset in (0.0, 0.0, 1000.0):
        evaluate(api, reference, estimate, time_offset_s=offset)
    _, in_sql = scrape(api.client)
    monkeypatch.setattr(metrics_module, "_duration_s", lambda _model, _dialect: None)
    _, in_python = scrape(api.client)
    for outcome, count in (("succeeded", 2), ("failed", 1)):
        labels = {"kind": "evaluation", "outcome": outcome}
        counted = buckets(in_python, "loceval_job_duration_seconds", **labels)
        assert counted == buckets(in_sql, "loceval_job_duration_seconds", **labels)
        assert counted[-1] == count
        total = "loceval_job_duration_seconds_sum"
        # SQLite's julianday() reads a time stamp to the millisecond only (its documentation:
        # "only the first three digits are significant"), so each duration in SQL may be off
        # by up to 1 ms, a sum of `count` of them by up to `count` ms.
        assert value(in_python, total, **labels) == pytest.approx(
            value(in_sql, total, **labels), rel=0, abs=count * 1e-3
        )


def test_durations_on_postgresql(
    tmp_path: Path,
    tum: tuple[bytes, bytes],
    postgres_url: str,
) -> None:
    """PostgreSQL computes the durations with its own SQL (epoch seconds)."""
    with open_api(tmp_path, database_url=postgres_url) as api:
        reference = api.dataset("a.txt", tum[0])["id"]
        estimate = api.dataset("b.txt", tum[1])["id"]
        assert evaluate(api, reference, estimate)["status"] == "succeeded"
        _, families = scrape(api.client)
    labels = {"kind": "evaluation", "outcome": "succeeded"}
    assert buckets(families, "loceval_job_duration_seconds", **labels)[-1] == 1
    assert 0 < value(families, "loceval_job_duration_seconds_sum", **labels) < 60
    assert value(families, "loceval_jobs", kind="evaluation", state="succeeded") == 1


@pytest.mark.slow
def test_jobs_run_by_a_worker_show_in_the_server_metrics(
    tmp_path: Path, tum: tuple[bytes, bytes]
) -> None:
    """``serve --no-consumer`` + ``worker``: the queue depth rises, then the job is counted."""
    (tmp_path / "gt.txt").write_bytes(tum[0])
    (tmp_path / "est.txt").write_bytes(tum[1])
    with running_server(tmp_path / "data", args=("--no-consumer",)) as server:
        with server.client() as client:
            reference = upload(client, tmp_path / "gt.txt")
            estimate = upload(client, tmp_path / "est.txt")
            queued = submit(
                client,
                {"dataset_id": reference["id"]},
                [{"dataset_id": estimate["id"]}],
                options=CHEAP,
            )
        with server.anonymous_client() as anonymous:
            _, waiting = scrape(anonymous)
        assert value(waiting, "loceval_queue_depth") == 1
        assert value(waiting, "loceval_jobs", kind="evaluation", state="queued") == 1
        worker = start_worker(server.data_dir, server.env)
        try:
            with server.client() as client:
                wait_for_evaluation(client, queued["id"])
        finally:
            worker.stop()
        with server.anonymous_client() as anonymous:
            text, done = scrape(anonymous)
    assert value(done, "loceval_queue_depth") == 0
    assert value(done, "loceval_jobs", kind="evaluation", state="succeeded") == 1
    labels = {"kind": "evaluation", "outcome": "succeeded"}
    assert value(done, "loceval_job_duration_seconds_count", **labels) == 1
    assert queued["id"] not in text
    assert reference["id"] not in text
