"""The summary's "recorded" column is when each recording started (its stamps), not its upload.

A backlog uploaded in one go keeps its real dates and order in the runs table and the trend.
"""

from __future__ import annotations

import datetime as dt
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from service.auth import create_key
from service.main import create_app
from service.schedules.runs import recording_start
from service.settings import Settings
from tests.bagfactory import NS, POSE, Poses, pose_records, random_poses, write_bag

UPLOADED = dt.datetime(2026, 11, 23, 7, 0, tzinfo=dt.UTC)


@pytest.mark.parametrize(
    ("inspection", "expected", "is_upload"),
    [
        # 1_710_000_000 s is 2024-03-09 16:00:00 UTC (date -u -d @1710000000)
        ({"start_ns": 1_710_000_000 * NS}, dt.datetime(2024, 3, 9, 16, 0, tzinfo=dt.UTC), False),
        ({"start_s": 1_710_000_000.5}, dt.datetime(2024, 3, 9, 16, 0, 0, 500_000, dt.UTC), False),
        (
            {"sources": [{"first_stamp_ns": 1_710_000_060 * NS}, {"first_stamp_ns": None}]},
            dt.datetime(2024, 3, 9, 16, 1, tzinfo=dt.UTC),
            False,
        ),
        ({"start_s": 0.0}, UPLOADED, True),  # TUM/KITTI: seconds since the device started
        ({"start_ns": 4_000_000_000 * NS}, UPLOADED, True),  # 2096: after the upload
        ({"sources": []}, UPLOADED, True),
    ],
)
def test_recording_start(
    inspection: dict[str, Any],
    expected: dt.datetime,
    is_upload: bool,  # noqa: FBT001  (a parametrized expectation)
) -> None:
    """The first stamp when it is a date between 2000 and the upload; else the upload time."""
    assert recording_start(inspection, UPLOADED) == (expected, is_upload)


@pytest.fixture
def client(tmp_path: Path) -> Iterator[TestClient]:
    """A client of a fresh service whose jobs run inside the requests."""
    app = create_app(Settings(data_dir=tmp_path / "data", queue_url="immediate"))
    with app.state.runtime.sessions() as session:
        key = create_key(session, "site")
    with TestClient(app, headers={"Authorization": f"Bearer {key}"}) as test_client:
        yield test_client


def _bag(tmp_path: Path, rng: np.random.Generator, name: str, start_s: int) -> Path:
    truth = random_poses(rng, 60, start_ns=start_s * NS, dt_ns=50_000_000)
    noisy = Poses(
        truth.stamps_ns,
        truth.positions + rng.normal(scale=0.01, size=truth.positions.shape),
        truth.quats,
    )
    records = pose_records("/gt", POSE, truth) + pose_records("/est", POSE, noisy)
    return write_bag(tmp_path / f"{name}.bag", records, fmt="rosbag1")


@pytest.mark.pdf
def test_backlog_keeps_its_recording_dates(
    client: TestClient, tmp_path: Path, rng: np.random.Generator
) -> None:
    """Runs of March to May 2024 uploaded newest first today: dated and sorted by stamps."""
    starts = {"march": 1_710_000_000, "april": 1_712_600_000, "may": 1_715_200_000}
    for name in ("may", "april", "march"):  # the backlog arrives in the wrong order
        with _bag(tmp_path, rng, name, starts[name]).open("rb") as fh:
            answer = client.post(
                "/api/v1/datasets", files={"file": (f"{name}.bag", fh)}, data={"tags": "l2"}
            )
        assert answer.status_code == 201, answer.text
    body = {
        "name": "Backlog",
        "cron": "0 7 * * mon",
        "selection": {"tags": ["l2"]},
        "template": {
            "reference": {"selector": "/gt"},
            "estimates": [{"selector": "/est", "name": "SLAM"}],
            "options": {"association": "nearest", "max_dt_s": 0.005},
        },
        "produce": {"summary_formats": ["summary.html"]},
    }
    schedule = client.post("/api/v1/schedules", json=body).json()
    run = client.post(f"/api/v1/schedules/{schedule['id']}/run").json()
    assert run["status"] == "succeeded", run
    html = client.get(run["artifacts"][0]["url"]).text
    runs_table = html[html.index('id="runs"') :]
    runs_table = runs_table[: runs_table.index("</table>")]
    stamps = re.findall(r'<time datetime="([^"]+)">([^<]+)</time>', runs_table)
    expected = [
        dt.datetime.fromtimestamp(starts[n], dt.UTC).isoformat(timespec="seconds")
        for n in ("march", "april", "may")
    ]
    assert [iso for iso, _ in stamps] == expected
    assert [text for _, text in stamps] == [
        "2024-03-09 16:00",
        "2024-04-08 18:13",
        "2024-05-08 20:26",
    ]
    assert "uploaded</small>" not in runs_table
    datasets = re.findall(r'class="dataset">([^<]+)', runs_table)
    assert datasets == ["march.bag", "april.bag", "may.bag"]
