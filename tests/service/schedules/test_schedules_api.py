"""Schedules over HTTP: create, run, summary report, webhook, bad input.

Jobs run inside the request (``queue_url="immediate"``), so ``POST .../run`` returns a
finished run; the firing itself is tested with a frozen clock in test_schedules_tick.py.
"""

from __future__ import annotations

import io
import json
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, HTTPServer
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from service.auth import create_key
from service.main import create_app
from service.schedules import runs as schedule_runs
from service.settings import Settings
from tests.bagfactory import POSE, Poses, pose_records, random_poses, write_bag
from tests.service._api_fixtures import schedule_body


@pytest.fixture
def client(tmp_path: Path) -> Iterator[TestClient]:
    """A client of a fresh service whose jobs run inside the requests (webhooks to 127.0.0.1)."""
    app = create_app(
        Settings(data_dir=tmp_path / "data", queue_url="immediate", webhook_allow="127.0.0.1")
    )
    with app.state.runtime.sessions() as session:
        key = create_key(session, "site")
    with TestClient(app, headers={"Authorization": f"Bearer {key}"}) as test_client:
        yield test_client


def _bag(tmp_path: Path, rng, name: str, *, noise: float, with_estimate: bool = True) -> Path:
    """A ROS 1 bag with the ground truth on /gt and a noisy estimate on /est."""
    truth = random_poses(rng, 120, dt_ns=50_000_000)
    records = pose_records("/gt", POSE, truth)
    if with_estimate:
        noisy = Poses(
            truth.stamps_ns,
            truth.positions + rng.normal(scale=noise, size=truth.positions.shape),
            truth.quats,
        )
        records += pose_records("/est", POSE, noisy)
    return write_bag(tmp_path / f"{name}.bag", records, fmt="rosbag1")


def _upload(client: TestClient, path: Path, tags: str) -> dict[str, Any]:
    with path.open("rb") as fh:
        response = client.post(
            "/api/v1/datasets", files={"file": (path.name, fh)}, data={"tags": tags}
        )
    assert response.status_code == 201, response.text
    return response.json()


@pytest.fixture
def recordings(client: TestClient, tmp_path: Path, rng) -> list[dict[str, Any]]:
    """Three runs of level 2, one recording without the estimate, one of another level."""
    uploaded = [
        _upload(client, _bag(tmp_path, rng, f"level2-run{k}", noise=0.01 * (k + 1)), "level2")
        for k in range(3)
    ]
    uploaded.append(
        _upload(
            client, _bag(tmp_path, rng, "level2-gt-only", noise=0, with_estimate=False), "level2"
        )
    )
    _upload(client, _bag(tmp_path, rng, "level3-run0", noise=0.01), "level3")
    return uploaded


def _pdf_text(data: bytes) -> str:
    from pypdf import PdfReader

    return "\n".join(page.extract_text() for page in PdfReader(io.BytesIO(data)).pages)


@pytest.mark.pdf
def test_a_run_reports_every_recording_and_its_table_matches(client: TestClient, recordings):
    """Trigger a run: each selected recording is evaluated; the summary PDF shows their figures."""
    created = client.post("/api/v1/schedules", json=schedule_body())
    assert created.status_code == 201, created.text
    schedule = created.json()
    assert schedule["next_fire_at"].startswith("2026-")
    run = client.post(f"/api/v1/schedules/{schedule['id']}/run")
    assert run.status_code == 202, run.text
    run = run.json()
    assert run["status"] == "succeeded", run
    assert run["trigger"] == "manual"
    rows = {r["dataset"]: r for r in run["rows"]}
    assert set(rows) == {r["name"] for r in recordings}  # level 3 is not selected
    failed = rows["level2-gt-only.bag"]
    assert failed["status"] == "failed"
    assert "/est" in failed["error"]
    pdf = client.get(f"/api/v1/schedules/{schedule['id']}/runs/{run['id']}/artifacts/summary.pdf")
    assert pdf.status_code == 200
    assert pdf.headers["content-type"] == "application/pdf"
    text = _pdf_text(pdf.content)
    html = client.get(run["artifacts"][0]["url"]).text
    for name, row in rows.items():
        assert name in text
        if row["status"] != "succeeded":
            continue
        evaluation = client.get(f"/api/v1/evaluations/{row['evaluation_id']}").json()
        ate = evaluation["result"]["estimates"][0]["ate"]["translation_m"]["rmse"]
        assert row["summary"][0]["ate_rmse_m"] == pytest.approx(ate, rel=1e-12)
        assert f"{ate:.3f}" in text
        assert f"{ate:.3f}" in html
    listed = client.get(f"/api/v1/schedules/{schedule['id']}/runs").json()
    assert [r["id"] for r in listed["items"]] == [run["id"]]


@pytest.mark.pdf
def test_an_empty_selection_gives_a_report_that_says_so(client: TestClient, recordings):
    """A selection matching nothing still succeeds, with a report saying nothing matched."""
    del recordings
    body = schedule_body(selection={"tags": ["nowhere"]})
    schedule = client.post("/api/v1/schedules", json=body).json()
    run = client.post(f"/api/v1/schedules/{schedule['id']}/run").json()
    assert run["status"] == "succeeded"
    assert run["rows"] == []
    html = client.get(run["artifacts"][0]["url"]).text
    assert "No recordings matched" in html
    pdf = client.get(run["artifacts"][1]["url"]).content
    assert "No recordings matched" in _pdf_text(pdf)


@pytest.mark.usefixtures("no_weasyprint")
def test_an_html_only_schedule_runs_without_weasyprint(client: TestClient, recordings):
    """Asked for summary.html only, a run lays out no PDF; asked for both, Typst makes it."""
    del recordings
    body = schedule_body(produce={"summary_formats": ["summary.html"]})
    schedule = client.post("/api/v1/schedules", json=body).json()
    run = client.post(f"/api/v1/schedules/{schedule['id']}/run").json()
    assert run["status"] == "succeeded", run
    assert [a["name"] for a in run["artifacts"]] == ["summary.html"]
    html = client.get(run["artifacts"][0]["url"]).text
    assert "level2-run0.bag" in html
    assert "data:image/svg+xml" in html  # the HTML's own plots, not the PDF's PNGs
    both = client.post("/api/v1/schedules", json=schedule_body()).json()
    made = client.post(f"/api/v1/schedules/{both['id']}/run").json()
    assert made["status"] == "succeeded", made  # the PDF needs no WeasyPrint (Typst)
    assert [a["name"] for a in made["artifacts"]] == ["summary.html", "summary.pdf"]
    pdf = client.get(made["artifacts"][1]["url"]).content
    assert "level2-run0.bag" in _pdf_text(pdf)


@pytest.mark.parametrize(
    ("change", "status", "match"),
    [
        ({"cron": "61 * * * *"}, 422, "Invalid cron expression"),
        ({"cron": "at seven"}, 422, "five fields"),
        ({"timezone": "Mars/Olympus"}, 422, "Unknown time zone 'Mars/Olympus'"),
        ({"webhook_url": "ftp://example.com/hook"}, 422, "webhook_url"),
        ({"name": ""}, 422, "name"),
        ({"selection": {"tags": ["a"], "extra": 1}}, 422, "extra"),
    ],
)
def test_bad_schedules_are_refused(client: TestClient, change, status, match):
    """Invalid cron, unknown zone, bad webhook or fields: 422 problem, nothing stored."""
    response = client.post("/api/v1/schedules", json=schedule_body(**change))
    assert response.status_code == status
    assert response.headers["content-type"] == "application/problem+json"
    assert match in response.text
    assert client.get("/api/v1/schedules").json()["count"] == 0


def test_bad_template_options_are_refused(client: TestClient):
    """The template's options are checked like POST /evaluations' (CLI messages)."""
    body = schedule_body()
    body["template"]["options"]["tolerance"] = "ten centimetres"
    response = client.post("/api/v1/schedules", json=body)
    assert response.status_code == 422
    assert "tolerance" in response.json()["detail"].lower()


def test_pause_resume_change_and_delete(client: TestClient):
    """PATCH pauses, resumes (next fire from now) and changes the cron; DELETE removes it."""
    schedule = client.post("/api/v1/schedules", json=schedule_body()).json()
    url = f"/api/v1/schedules/{schedule['id']}"
    paused = client.patch(url, json={"paused": True}).json()
    assert paused["paused"] is True
    changed = client.patch(url, json={"cron": "30 6 * * *", "paused": False}).json()
    assert (changed["paused"], changed["cron"]) == (False, "30 6 * * *")
    assert changed["next_fire_at"] != schedule["next_fire_at"]
    bad = client.patch(url, json={"timezone": "Nowhere/Else"})
    assert bad.status_code == 422
    assert client.delete(url).status_code == 204
    assert client.get(url).status_code == 404
    assert client.post(f"{url}/run").status_code == 404


@pytest.mark.parametrize(
    "field", ["produce", "selection", "template", "paused", "name", "timezone", "cron"]
)
def test_a_null_for_a_field_that_cannot_be_empty_is_refused(client: TestClient, field: str):
    """PATCH with null for a required field: 422 naming it, nothing saved, the list still works."""
    schedule = client.post("/api/v1/schedules", json=schedule_body()).json()
    url = f"/api/v1/schedules/{schedule['id']}"
    response = client.patch(url, json={field: None, "cron": "15 5 * * *"} | {field: None})
    assert response.status_code == 422, response.text
    body = response.json()
    assert response.headers["content-type"].startswith("application/problem+json")
    assert [e["loc"] for e in body["errors"]] == [["body", field]], body
    assert f"body.{field}: may be left out" in body["detail"]
    shown = client.get(url)
    assert shown.status_code == 200, shown.text
    kept = {k: v for k, v in shown.json().items() if k != "next_fire_at"}
    assert kept == {
        k: v for k, v in schedule.items() if k not in {"next_fire_at", "webhook_secret"}
    }
    assert client.get("/api/v1/schedules").status_code == 200
    assert client.post(f"{url}/run").status_code == 202


def test_the_patch_schema_says_which_fields_may_be_null(client: TestClient):
    """The OpenAPI document: only webhook_url of a patch may be null; no field is required."""
    schema = client.get("/openapi.json").json()["components"]["schemas"]["SchedulePatch"]
    nullable = {
        name
        for name, prop in schema["properties"].items()
        if {"type": "null"} in prop.get("anyOf", []) or prop.get("type") == "null"
    }
    assert nullable == {"webhook_url"}
    assert "required" not in schema
    assert all("default" not in p for n, p in schema["properties"].items() if n != "webhook_url")


def test_other_projects_see_nothing(client: TestClient):
    """Another project's key gets 404 for the schedule, its runs and its reports."""
    schedule = client.post("/api/v1/schedules", json=schedule_body(selection={})).json()
    run = client.post(f"/api/v1/schedules/{schedule['id']}/run").json()
    runtime = client.app.state.runtime  # type: ignore[attr-defined]
    with runtime.sessions() as session:
        other = create_key(session, "elsewhere")
    headers = {"Authorization": f"Bearer {other}"}
    base = f"/api/v1/schedules/{schedule['id']}"
    for path in (
        base,
        f"{base}/runs",
        f"{base}/runs/{run['id']}",
        f"{base}/runs/{run['id']}/artifacts/summary.pdf",
    ):
        assert client.get(path, headers=headers).status_code == 404
    assert client.patch(base, json={"paused": True}, headers=headers).status_code == 404
    assert client.get("/api/v1/schedules", headers=headers).json()["count"] == 0


class _Hook:
    """A local webhook receiver that answers with a fixed status."""

    def __init__(self, status: int) -> None:
        self.bodies: list[dict[str, Any]] = []
        hook = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                length = int(self.headers["Content-Length"])
                hook.bodies.append(json.loads(self.rfile.read(length)))
                self.send_response(status)
                self.end_headers()

            def log_message(self, *_args: object) -> None:
                return

        self.server = HTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_port}/hook"
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def no_backoff(monkeypatch):
    """Webhook retries are the queue's: no thread sleeps between attempts (immediate mode)."""

    def refuse(seconds: float) -> None:
        msg = f"a webhook attempt slept {seconds} s in the worker thread"
        raise AssertionError(msg)

    monkeypatch.setattr(schedule_runs.time, "sleep", refuse)


@pytest.mark.pdf
@pytest.mark.usefixtures("no_backoff")
def test_the_webhook_receives_the_summary(client: TestClient, recordings):
    """A finished run posts its links and each recording's verdicts to the webhook."""
    del recordings
    hook = _Hook(204)
    try:
        body = schedule_body(webhook_url=hook.url)
        schedule = client.post("/api/v1/schedules", json=body).json()
        run = client.post(f"/api/v1/schedules/{schedule['id']}/run").json()
    finally:
        hook.close()
    (payload,) = hook.bodies
    assert payload["run"]["id"] == run["id"]
    assert payload["run"]["status"] == "succeeded"
    assert set(payload["links"]) == {"summary.html", "summary.pdf"}
    verdicts = {r["dataset"]: [s["verdict"] for s in r["systems"]] for r in payload["recordings"]}
    assert verdicts["level2-run0.bag"] == ["pass"]
    assert verdicts["level2-gt-only.bag"] == []
    recorded = client.get(f"/api/v1/schedules/{schedule['id']}/runs/{run['id']}").json()
    assert recorded["webhook"]["delivered"] is True


@pytest.mark.pdf
@pytest.mark.usefixtures("no_backoff")
def test_a_failing_webhook_is_retried_and_recorded(client: TestClient):
    """A webhook answering 500 is tried three times; the run still succeeds."""
    hook = _Hook(500)
    try:
        body = schedule_body(webhook_url=hook.url, selection={"tags": ["none"]})
        schedule = client.post("/api/v1/schedules", json=body).json()
        run = client.post(f"/api/v1/schedules/{schedule['id']}/run").json()
    finally:
        hook.close()
    assert len(hook.bodies) == 3
    recorded = client.get(f"/api/v1/schedules/{schedule['id']}/runs/{run['id']}").json()
    assert recorded["status"] == "succeeded"
    assert recorded["webhook"]["delivered"] is False
    assert [a["status"] for a in recorded["webhook"]["attempts"]] == [500, 500, 500]


@pytest.mark.pdf
@pytest.mark.usefixtures("no_backoff")
def test_an_unreachable_webhook_does_not_fail_the_run(client: TestClient):
    """A webhook nobody listens on is recorded as undelivered; the run is not affected."""
    body = schedule_body(webhook_url="http://127.0.0.1:9/hook", selection={"tags": ["none"]})
    schedule = client.post("/api/v1/schedules", json=body).json()
    run = client.post(f"/api/v1/schedules/{schedule['id']}/run").json()
    assert run["status"] == "succeeded"
    recorded = client.get(f"/api/v1/schedules/{schedule['id']}/runs/{run['id']}").json()
    assert recorded["webhook"]["delivered"] is False
    assert len(recorded["webhook"]["attempts"]) == 3
    assert np.all([a.get("error") for a in recorded["webhook"]["attempts"]])
