"""A schedule with a pinned baseline: every run is compared with it, and its summary says so."""

from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from tests.service._api_fixtures import schedule_body
from tests.service.schedules.test_schedules_api import _bag, _upload, client

__all__ = ["client"]


def test_runs_against_a_pinned_baseline(client: TestClient, tmp_path: Path, rng):
    """The baseline evaluation's AMCL is each run's counterpart: the run's result has the
    difference and verdict, and summary.html shows the section with each run's rows."""
    baseline_bag = _upload(client, _bag(tmp_path, rng, "level2-release", noise=0.01), "release")
    for k in range(2):
        _upload(client, _bag(tmp_path, rng, f"level2-run{k}", noise=0.03), "level2")
    pinned = client.post(
        "/api/v1/evaluations",
        json={
            "reference": {"dataset_id": baseline_bag["id"], "selector": "/gt", "name": "OptiTrack"},
            "estimates": [{"dataset_id": baseline_bag["id"], "selector": "/est", "name": "AMCL"}],
        },
    ).json()
    assert pinned["status"] == "succeeded", pinned
    body = schedule_body(produce={"summary_formats": ["summary.html"]})
    body["template"]["options"]["baseline"] = pinned["id"]
    created = client.post("/api/v1/schedules", json=body)
    assert created.status_code == 201, created.text
    run = client.post(f"/api/v1/schedules/{created.json()['id']}/run").json()
    assert run["status"] == "succeeded", run
    evaluated = [r for r in run["rows"] if r["status"] == "succeeded"]
    assert len(evaluated) == 2
    for row in evaluated:
        result = client.get(f"/api/v1/evaluations/{row['evaluation_id']}").json()["result"]
        comparisons = result["baseline"]["comparisons"]
        ate = next(c for c in comparisons if c["metric"] == "ate_rmse")
        assert ate["name"] == "AMCL"
        assert not ate["paired"]  # another recording: nothing pairs its poses
        assert ate["verdict"] == "worse"  # 3 cm of noise now, 1 cm in the release
    html = client.get(run["artifacts"][0]["url"]).text
    assert "Against the baseline" in html
    assert f"evaluation {pinned['id']}" in html
    assert html.count('class="baseline-worse"') == 4  # ATE and RPE of each of the 2 runs


@pytest.mark.parametrize(("baseline", "status"), [("no-such-evaluation", 404)])
def test_a_schedule_names_only_an_existing_baseline(client: TestClient, baseline, status):
    """A pinned baseline that is no evaluation of the project is refused at creation."""
    body = schedule_body()
    body["template"]["options"]["baseline"] = baseline
    response = client.post("/api/v1/schedules", json=body)
    assert response.status_code == status, response.text
