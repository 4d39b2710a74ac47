"""``POST /api/v1/ranging``: anchors and ranges as uploads, run as an evaluation job."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests import bagfactory as bf
from tests.factories import write_tum
from tests.radio_factory import (
    make_anchors,
    make_ranges,
    make_reference,
    write_anchors_csv,
    write_ranges_csv,
)
from tests.service._api_fixtures import Api, assert_problem

CHEAP = {"formats": ["result.json"]}


@pytest.fixture
def uploads(api: Api, rng: np.random.Generator, tmp_path: Path) -> dict[str, str]:
    """Upload reference, anchors and ranges; return their dataset ids by role."""
    recording = make_ranges(rng, nlos_share=0.03)
    files = {
        "reference": write_tum(tmp_path / "truth.txt", make_reference()),
        "anchors": write_anchors_csv(tmp_path / "anchors.csv", make_anchors()),
        "ranges": write_ranges_csv(tmp_path / "ranges.csv", recording.ranges),
    }
    return {role: api.dataset(path.name, path.read_bytes())["id"] for role, path in files.items()}


def _post(api: Api, body: dict[str, Any]) -> Any:
    return api.client.post("/api/v1/ranging", headers=api.headers, json=body)


def test_uploads_are_recognised(api: Api, uploads: dict[str, str]) -> None:
    """The upload inspection names the ranges table and the anchors' survey (points)."""
    for role, kind in (("anchors", "points"), ("ranges", "ranges")):
        dataset = api.client.get(f"/api/v1/datasets/{uploads[role]}", headers=api.headers).json()
        assert dataset["kind"] == kind
        assert dataset["inspection"]["format"] == kind
    anchors = api.client.get(f"/api/v1/datasets/{uploads['anchors']}", headers=api.headers)
    assert anchors.json()["inspection"]["ids"] == list(make_anchors().ids)


def test_ranging_job_runs(api: Api, uploads: dict[str, str]) -> None:
    """202; the job ran: one summary row per solver, the result's ranging object."""
    body = {
        "reference": {"dataset_id": uploads["reference"]},
        "anchors": uploads["anchors"],
        "ranges": uploads["ranges"],
        "options": CHEAP,
    }
    response = _post(api, body)
    assert response.status_code == 202, response.text
    evaluation = response.json()
    assert evaluation["status"] == "succeeded", evaluation["error"]
    assert [row["name"] for row in evaluation["summary"]] == ["nlls", "minmax"]
    assert [e["name"] for e in evaluation["estimates"]] == ["nlls", "minmax"]
    assert evaluation["options"]["align"] == "none"  # the ranging default
    full = api.client.get(f"/api/v1/evaluations/{evaluation['id']}", headers=api.headers).json()
    result = full["result"]
    assert result["ranging"]["unused_anchors"] == ["FAR"]
    assert result["ranging"]["overall"]["n"] > 6000
    assert result["options"]["planar"] is True
    assert [i["role"] for i in result["inputs"]] == ["reference", "anchors", "ranges"]
    assert [i["file"] for i in result["inputs"]][1:] == ["anchors.csv", "ranges.csv"]


def test_ranges_from_a_bag_topic(api: Api, rng: np.random.Generator, tmp_path: Path) -> None:
    """Ranges as {dataset_id, selector} of a bag's Range topic; 3D with one solver."""
    ranges = make_ranges(rng, end_s=20.0).ranges
    ids = np.array(ranges.anchors.ids)[ranges.anchor_index]
    records = [
        bf.Record("/uwb/range", bf.RANGE, int(t), (int(t), float(r)), frame_id=str(i))
        for t, r, i in zip(ranges.stamps_ns, ranges.range_m, ids, strict=True)
    ]
    bag = bf.write_bag(tmp_path / "uwb.bag", records, fmt="rosbag1")
    reference = write_tum(tmp_path / "truth.txt", make_reference())
    anchors = write_anchors_csv(tmp_path / "anchors.csv", make_anchors())
    body = {
        "reference": {"dataset_id": api.dataset("truth.txt", reference.read_bytes())["id"]},
        "anchors": api.dataset("anchors.csv", anchors.read_bytes())["id"],
        "ranges": {
            "dataset_id": api.dataset("uwb.bag", bag.read_bytes())["id"],
            "selector": "/uwb/range",
        },
        "options": {**CHEAP, "dims": "3", "solve": ["nlls"]},
    }
    evaluation = _post(api, body).json()
    assert evaluation["status"] == "succeeded", evaluation["error"]
    [row] = evaluation["summary"]
    assert row["name"] == "nlls"
    assert row["matched"] == 199  # 0.1 s epochs from 0 to 19.9 s


def test_bad_requests_are_4xx(api: Api, uploads: dict[str, str]) -> None:
    """Wrong dataset kinds, a missing dataset, bad options: problems before anything runs."""
    base = {
        "reference": {"dataset_id": uploads["reference"]},
        "anchors": uploads["anchors"],
        "ranges": uploads["ranges"],
        "options": CHEAP,
    }
    swapped = {**base, "anchors": uploads["ranges"]}
    assert_problem(_post(api, swapped), 422, detail="not an anchors table")
    as_reference = {**base, "reference": {"dataset_id": uploads["ranges"]}}
    assert_problem(_post(api, as_reference), 422, detail="radio ranges table, not a trajectory")
    missing = {**base, "ranges": "no-such-dataset"}
    assert_problem(_post(api, missing), 404, detail="No dataset 'no-such-dataset'")
    offset = {**base, "options": {**CHEAP, "tag_offset_xyz": "1 2"}}
    problem = assert_problem(_post(api, offset), 422, detail="tag offset takes three numbers")
    assert problem["option"] == "options.tag_offset_xyz"
    solver = {**base, "options": {**CHEAP, "solve": ["kalman"]}}
    assert_problem(_post(api, solver), 422, detail="solve")
    device = {**base, "options": {**CHEAP, "offset": "0 0 0.2"}}
    assert_problem(_post(api, device), 422, detail="takes no device offset")
    baseline = {**base, "options": {**CHEAP, "baseline": "earlier/result.json"}}
    problem = assert_problem(_post(api, baseline), 422, detail="solvers have none")
    assert problem["option"] == "options.baseline"
    coverage = {**base, "options": {**CHEAP, "min_trial_coverage": 0.8}}
    problem = assert_problem(_post(api, coverage), 422, detail="has none: leave it out")
    assert problem["option"] == "options.min_trial_coverage"
    assert api.evaluation_count() == 0


def test_no_time_overlap_fails_the_job(
    api: Api, uploads: dict[str, str], rng: np.random.Generator, tmp_path: Path
) -> None:
    """Ranges of another day: the evaluation fails with the reader's problem (no 500)."""
    later = make_ranges(rng, t0_ns=2_000_000_000 * 10**9, end_s=5.0).ranges
    path = write_ranges_csv(tmp_path / "later.csv", later)
    body = {
        "reference": {"dataset_id": uploads["reference"]},
        "anchors": uploads["anchors"],
        "ranges": api.dataset("later.csv", path.read_bytes())["id"],
        "options": CHEAP,
    }
    evaluation = _post(api, body).json()
    assert evaluation["status"] == "failed"
    assert evaluation["error"]["status"] == 422
    assert "same clock" in evaluation["error"]["detail"]
