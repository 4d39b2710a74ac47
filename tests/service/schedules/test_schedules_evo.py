"""Schedules take uploaded evo result zips beside the recordings they evaluate (issue 28).

The zips are evo 1.38.1's own (``tests/data/evo_results``, commands in its README); the
figures asserted are the ones evo printed when it wrote them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from service.db import Schedule, ScheduleRun
from service.schedules.runs import webhook_payload
from tests.bagfactory import POSE, Poses, pose_records, random_poses, write_bag
from tests.service._api_fixtures import Api, assert_no_server_paths, schedule_body

EVO = Path(__file__).parents[2] / "data" / "evo_results"
APE_RMSE = 0.5123009339164919
"""evo_ape's rmse of nav2_amcl_odom_ape_se3.zip."""
RPE_RMSE = 0.04056265558900615
"""evo_rpe's rmse of nav2_amcl_odom_rpe_se3.zip."""
HTML_ONLY = {"summary_formats": ["summary.html"]}


def _bag(folder: Path, rng: np.random.Generator, name: str) -> bytes:
    """A ROS 1 bag with the ground truth on /gt and a noisy estimate on /est."""
    truth = random_poses(rng, 120, dt_ns=50_000_000)
    noisy = Poses(
        truth.stamps_ns,
        truth.positions + rng.normal(scale=0.02, size=truth.positions.shape),
        truth.quats,
    )
    records = pose_records("/gt", POSE, truth) + pose_records("/est", POSE, noisy)
    return write_bag(folder / f"{name}.bag", records, fmt="rosbag1").read_bytes()


def _zip(api: Api, name: str, **fields: str) -> dict[str, Any]:
    return api.dataset(name, (EVO / name).read_bytes(), **fields)


def _run(api: Api, body: dict[str, Any]) -> dict[str, Any]:
    created = api.client.post("/api/v1/schedules", headers=api.headers, json=body)
    assert created.status_code == 201, created.text
    run = api.client.post(f"/api/v1/schedules/{created.json()['id']}/run", headers=api.headers)
    assert run.status_code == 202, run.text
    answer: dict[str, Any] = run.json()
    assert answer["status"] == "succeeded", answer
    return answer


def test_evo_zips_join_the_summary_with_their_source_marked(api: Api, tmp_path: Path, rng) -> None:
    """A tagged zip is picked, a named one is added; evo's RMSE stands in their rows, marked evo."""
    api.dataset("level2-run0.bag", _bag(tmp_path, rng, "level2-run0"), tags="level2")
    picked = _zip(api, "nav2_amcl_odom_ape_se3.zip", tags="level2")
    named = _zip(api, "nav2_amcl_odom_rpe_se3.zip")  # no tag: only the id brings it in
    _zip(api, "nav2_amcl_odom_ape_origin.zip", tags="other")  # neither picked nor named
    selection = {"tags": ["level2"], "evo_results": [{"dataset_id": named["id"], "name": "AMCL"}]}
    run = _run(api, schedule_body(selection=selection, produce=HTML_ONLY))

    rows = {r["dataset"]: r for r in run["rows"]}
    assert set(rows) == {"level2-run0.bag", picked["name"], named["name"]}
    assert rows["level2-run0.bag"].get("source") is None  # evaluated by loceval
    ape, rpe = rows[picked["name"]], rows[named["name"]]
    assert (ape["status"], ape["source"], ape["evaluation_id"]) == ("succeeded", "evo", None)
    assert ape["summary"] == [
        {
            "name": "/odom",
            "ate_rmse_m": APE_RMSE,
            "rpe_rmse_m": None,
            "matched": 83,
            "verdict": None,
        }
    ]
    assert rpe["summary"][0]["name"] == "AMCL"  # the name the schedule gave it
    assert rpe["summary"][0]["rpe_rmse_m"] == RPE_RMSE
    assert rpe["summary"][0]["ate_rmse_m"] is None
    assert "evo gives no confidence interval and no verdict" in rpe["note"]
    assert "RPE w.r.t. translation part (m), for delta = 1 (frames)" in rpe["note"]

    html = api.client.get(run["artifacts"][0]["url"], headers=api.headers).text
    assert html.count('class="badge badge-source"') == 2
    assert f"{APE_RMSE:.3f}" in html
    assert f"{RPE_RMSE:.3f}" in html
    assert "2 rows marked evo are an uploaded result zip" in html
    assert "and 1 evo result zip named by id" in html

    runtime = api.app.state.runtime
    with runtime.sessions() as session:
        stored = session.get_one(ScheduleRun, run["id"])
        schedule = session.get_one(Schedule, stored.schedule_id)
    payload = webhook_payload(runtime, stored, schedule)
    sources = {r["dataset"]: r["source"] for r in payload["recordings"]}
    assert sources == {"level2-run0.bag": "loceval", picked["name"]: "evo", named["name"]: "evo"}


def test_a_zip_in_degrees_is_shown_without_a_figure_in_metres(api: Api) -> None:
    """An APE of rotation angles keeps its row, with no ATE and a note saying what it holds."""
    zipped = _zip(api, "nav2_amcl_odom_ape_angle_deg.zip", tags="level2")
    run = _run(api, schedule_body(produce=HTML_ONLY))
    (row,) = run["rows"]
    assert row["dataset_id"] == zipped["id"]
    assert row["summary"][0]["ate_rmse_m"] is None
    assert row["summary"][0]["rpe_rmse_m"] is None
    assert "rotation angle in degrees" in row["note"]
    assert "RMSE 4.06361 deg: not a translation error in metres" in row["note"]


def test_naming_what_is_no_evo_result_is_refused(api: Api, tmp_path: Path, rng) -> None:
    """A missing id or another project's zip is a 404, a recording in evo_results a 422."""
    bag = api.dataset("level2-run0.bag", _bag(tmp_path, rng, "level2-run0"))
    other = api.client.post(
        "/api/v1/datasets",
        headers=api.other_headers,
        files={"file": ("theirs.zip", (EVO / "nav2_amcl_odom_ape_se3.zip").read_bytes())},
    ).json()
    cases = {
        "no-such-id": (404, "no dataset 'no-such-id' in this project"),
        other["id"]: (404, f"no dataset {other['id']!r} in this project"),
        bag["id"]: (422, "'level2-run0.bag' is a bag upload, not an evo result zip"),
    }
    for dataset_id, (status, expected) in cases.items():
        body = schedule_body(selection={"evo_results": [{"dataset_id": dataset_id}]})
        answer = api.client.post("/api/v1/schedules", headers=api.headers, json=body)
        assert answer.status_code == status, answer.text
        detail = answer.json()["detail"]
        assert "selection.evo_results[0].dataset_id" in detail
        assert expected in detail
    created = api.client.post("/api/v1/schedules", headers=api.headers, json=schedule_body())
    patch = {"selection": {"evo_results": [{"dataset_id": bag["id"]}]}}
    url = f"/api/v1/schedules/{created.json()['id']}"
    answer = api.client.patch(url, headers=api.headers, json=patch)
    assert answer.status_code == 422, answer.text
    assert "not an evo result zip" in answer.json()["detail"]


def test_a_damaged_or_deleted_zip_fails_its_row_not_the_run(api: Api) -> None:
    """A stored zip damaged since upload, or a named one deleted, is a failed row with why."""
    damaged = _zip(api, "nav2_amcl_odom_ape_se3.zip", tags="level2")
    gone = _zip(api, "nav2_amcl_odom_rpe_se3.zip")
    kept = _zip(api, "nav2_amcl_odom_ape_origin.zip", tags="level2")
    stored = [
        p
        for p in api.stored()
        if p.read_bytes() == (EVO / "nav2_amcl_odom_ape_se3.zip").read_bytes()
    ]
    assert len(stored) == 1
    stored[0].write_bytes(b"PK\x03\x04 cut off")
    body = schedule_body(
        selection={"tags": ["level2"], "evo_results": [{"dataset_id": gone["id"]}]}
    )
    created = api.client.post("/api/v1/schedules", headers=api.headers, json=body)
    assert created.status_code == 201, created.text
    assert (
        api.client.delete(f"/api/v1/datasets/{gone['id']}", headers=api.headers).status_code == 204
    )
    run = api.client.post(f"/api/v1/schedules/{created.json()['id']}/run", headers=api.headers)
    run = run.json()
    assert run["status"] == "succeeded", run
    rows = {r["dataset_id"]: r for r in run["rows"]}
    assert rows[kept["id"]]["status"] == "succeeded"
    assert rows[damaged["id"]]["status"] == "failed"
    assert "'nav2_amcl_odom_ape_se3.zip' cannot be read" in rows[damaged["id"]]["error"]
    assert_no_server_paths(rows[damaged["id"]]["error"], api.data_dir)
    assert rows[gone["id"]]["status"] == "failed"
    assert "is no longer in the project" in rows[gone["id"]]["error"]
