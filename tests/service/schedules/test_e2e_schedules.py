"""Schedules through a real ``loceval serve``: a triggered run's summary PDF, a missed fire.

The runs' recordings are ROS 1 bags written here (ground truth on /gt, an estimate on
/est); the summary's table must show each evaluation's own figures.
"""

from __future__ import annotations

import datetime as dt
import io
import time
from pathlib import Path
from typing import Any

import httpx2
import pytest
from sqlalchemy import create_engine, update
from sqlalchemy.orm import Session

from service.db import Schedule
from tests.bagfactory import POSE, Poses, pose_records, random_poses, write_bag
from tests.service._api_fixtures import schedule_body
from tests.service.conftest import running_server, upload

pytestmark = pytest.mark.slow


def _bag(tmp_path: Path, rng, name: str, *, noise: float) -> Path:
    truth = random_poses(rng, 150, dt_ns=50_000_000)
    moved = truth.positions + rng.normal(scale=noise, size=truth.positions.shape)
    records = pose_records("/gt", POSE, truth)
    records += pose_records("/est", POSE, Poses(truth.stamps_ns, moved, truth.quats))
    return write_bag(tmp_path / f"{name}.bag", records, fmt="rosbag1")


SCHEDULE = schedule_body()


def _wait_for_run(client: httpx2.Client, schedule_id: str, timeout: float = 180) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    runs: list[dict[str, Any]] = []
    while time.monotonic() < deadline:
        runs = client.get(f"/api/v1/schedules/{schedule_id}/runs").json()["items"]
        if runs and runs[0]["status"] in {"succeeded", "failed"}:
            return runs[0]
        time.sleep(0.3)
    pytest.fail(f"no finished run of {schedule_id} within {timeout} s: {runs}")


@pytest.mark.pdf
def test_trigger_a_run_and_read_its_summary(tmp_path: Path, rng):
    """Upload three runs, trigger the schedule; the PDF table equals each evaluation's ATE."""
    from pypdf import PdfReader

    with running_server(tmp_path / "data") as server, server.client() as client:
        for k in range(3):
            upload(
                client, _bag(tmp_path, rng, f"level2-run{k}", noise=0.02 * (k + 1)), tags="level2"
            )
        schedule = client.post("/api/v1/schedules", json=SCHEDULE).json()
        started = client.post(f"/api/v1/schedules/{schedule['id']}/run")
        assert started.status_code == 202, started.text
        run = _wait_for_run(client, schedule["id"])
        assert run["status"] == "succeeded", run
        pdf = client.get(
            f"/api/v1/schedules/{schedule['id']}/runs/{run['id']}/artifacts/summary.pdf"
        )
        assert pdf.status_code == 200
        text = "\n".join(p.extract_text() for p in PdfReader(io.BytesIO(pdf.content)).pages)
        assert len(run["rows"]) == 3
        for row in run["rows"]:
            evaluation = client.get(f"/api/v1/evaluations/{row['evaluation_id']}").json()
            ate = evaluation["result"]["estimates"][0]["ate"]["translation_m"]["rmse"]
            rpe = evaluation["result"]["estimates"][0]["rpe"]["translation_m"]["rmse"]
            assert row["dataset"] in text
            assert f"{ate:.3f}" in text
            assert f"{rpe:.3f}" in text


@pytest.mark.pdf
def test_a_fire_missed_while_down_runs_once_at_start(tmp_path: Path, rng):
    """A schedule due while the service was stopped runs once when it starts, and says so."""
    data = tmp_path / "data"
    with running_server(data) as server, server.client() as client:
        upload(client, _bag(tmp_path, rng, "level2-run0", noise=0.02), tags="level2")
        schedule = client.post("/api/v1/schedules", json=SCHEDULE).json()
        key = server.api_key
    three_days_ago = dt.datetime.now(dt.UTC) - dt.timedelta(days=3)
    engine = create_engine(f"sqlite:///{data / 'loceval.db'}")
    with Session(engine) as session:
        session.execute(
            update(Schedule)
            .where(Schedule.id == schedule["id"])
            .values(next_fire_at=three_days_ago.replace(second=0, microsecond=0))
        )
        session.commit()
    engine.dispose()
    with running_server(data, api_key=key) as server, server.client() as client:
        run = _wait_for_run(client, schedule["id"])
        runs = client.get(f"/api/v1/schedules/{schedule['id']}/runs").json()["items"]
        later = client.get(f"/api/v1/schedules/{schedule['id']}").json()
    assert len(runs) == 1
    assert run["trigger"] == "missed"
    assert run["status"] == "succeeded"
    assert "was not running" in run["note"]
    assert later["next_fire_at"] > dt.datetime.now(dt.UTC).isoformat()
