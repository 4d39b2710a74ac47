"""Control points over HTTP: a survey and a visits table upload as datasets and evaluate.

The recording is a 3 x 4 grid at 30 cm visited twice with 3 s stops (a smaller version of
the CLI test's 5 x 9 grid, so the request stays quick); its figures are compared with the
core's ``evaluate_checkpoints`` on the same files.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from loceval.checkpoints.fit import evaluate_checkpoints
from loceval.readers.points import read_visits
from tests.checkpoint_factory import (
    StopAndGo,
    estimate_tum_rows,
    grid_points,
    stop_and_go,
    write_points,
)
from tests.checkpoint_factory import write_visits as write_true_visits
from tests.service._api_fixtures import Api, assert_problem

FORMATS = ["result.json", "errors.csv"]


@pytest.fixture
def recording(rng: np.random.Generator, tmp_path: Path) -> StopAndGo:
    """A 3 x 4 grid visited twice; survey, TUM estimate and visits under tmp_path/in."""
    folder = tmp_path / "in"
    folder.mkdir()
    rec = stop_and_go(rng, grid_points(3, 4), passes=2)
    write_points(folder / "survey.csv", rec.points)
    rows = estimate_tum_rows(rec)
    (folder / "est.txt").write_text("\n".join(rows) + "\n")
    write_true_visits(folder / "visits.csv", rec)
    return rec


def _upload(api: Api, folder: Path, name: str) -> dict[str, Any]:
    return api.dataset(name, (folder / name).read_bytes())


def _body(reference: str, estimate: str, **options: object) -> dict[str, Any]:
    return {
        "reference": {"dataset_id": reference},
        "estimates": [{"dataset_id": estimate, "name": "slam"}],
        "options": {"align": "none", "formats": FORMATS, **options},
    }


def test_uploads_are_inspected(api: Api, recording: StopAndGo, tmp_path: Path) -> None:
    """A survey uploads as kind points (no selector), a visits table as kind visits."""
    survey = _upload(api, tmp_path / "in", "survey.csv")
    visits = _upload(api, tmp_path / "in", "visits.csv")
    assert survey["inspection"]["format"] == "points"
    assert survey["inspection"]["points"] == 12
    assert survey["inspection"]["sources"] == []
    assert visits["inspection"]["format"] == "visits"
    assert visits["inspection"]["visits"] == len(recording.visit_ids) == 24


@pytest.mark.parametrize("with_visits", [False, True], ids=["auto", "visits-dataset"])
def test_evaluate_against_control_points(
    api: Api, recording: StopAndGo, tmp_path: Path, *, with_visits: bool
) -> None:
    """The job scores the visits as the core does; summary and errors.csv follow."""
    folder = tmp_path / "in"
    survey = _upload(api, folder, "survey.csv")["id"]
    estimate = _upload(api, folder, "est.txt")["id"]
    options: dict[str, object] = {}
    core_visits = None
    if with_visits:
        options["visits"] = _upload(api, folder, "visits.csv")["id"]
        core_visits = read_visits(folder / "visits.csv", recording.points)
    response = api.evaluate(_body(survey, estimate, **options))
    assert response.status_code == 202, response.text
    evaluation = response.json()
    assert evaluation["status"] == "succeeded", evaluation["error"]
    core = evaluate_checkpoints(recording.points, recording.estimate, visits=core_visits)
    [row] = evaluation["summary"]
    assert row["ate_rmse_m"] == pytest.approx(core.stats.rmse, abs=1e-6)
    url = f"/api/v1/evaluations/{evaluation['id']}"
    full = api.client.get(url, headers=api.headers).json()["result"]
    assert full["reference"]["kind"] == "control_points"
    assert full["reference"]["source"] == "points:survey.csv"  # the upload's name, no folders
    [entry] = full["estimates"]
    assert [v["id"] for v in entry["checkpoints"]["visits"]] == recording.visit_ids
    assert entry["checkpoints"]["score"] == pytest.approx(
        core.to_dict()["checkpoints"]["score"]  # type: ignore[index]
    )
    text = api.client.get(f"{url}/artifacts/errors.csv", headers=api.headers).text
    rows = list(csv.DictReader(io.StringIO(text)))
    assert len(rows) == 24
    np.testing.assert_allclose(
        [float(r["error_m"]) for r in rows], [v.error_m for v in core.visits], atol=1e-9
    )


def test_visits_must_be_a_visits_table(api: Api, recording: StopAndGo, tmp_path: Path) -> None:
    """A trajectory given as the visits dataset is refused before the job is queued."""
    del recording
    folder = tmp_path / "in"
    survey = _upload(api, folder, "survey.csv")["id"]
    estimate = _upload(api, folder, "est.txt")["id"]
    response = api.evaluate(_body(survey, estimate, visits=estimate))
    assert_problem(response, 422, detail=r"^options\.visits: The visits dataset 'est.txt' is a")


def test_a_tolerance_is_refused_beside_control_points(
    api: Api, recording: StopAndGo, tmp_path: Path
) -> None:
    """Control points have no tolerance verdict: a tolerance (and a gate on it) is a 422.

    Before, the tolerance was ignored and ``fail_on: fail`` passed a 20 mm error against a
    10 mm tolerance: a gate that judged nothing.
    """
    del recording
    folder = tmp_path / "in"
    survey = _upload(api, folder, "survey.csv")["id"]
    estimate = _upload(api, folder, "est.txt")["id"]
    response = api.evaluate(_body(survey, estimate, tolerance="0.01@95", fail_on=["fail"]))
    problem = assert_problem(response, 422, detail="no verdict to gate on")
    assert problem["option"] == "options.tolerance"
    assert api.evaluation_count() == 0


def test_bad_visits_fail_the_job_with_a_problem(
    api: Api, recording: StopAndGo, tmp_path: Path
) -> None:
    """A visit naming an unknown point fails the job with a 422 problem naming the id."""
    del recording
    folder = tmp_path / "in"
    (folder / "bad.csv").write_text("id,t_start,t_end\nQ7,1700000002.0,1700000004.0\n")
    survey = _upload(api, folder, "survey.csv")["id"]
    estimate = _upload(api, folder, "est.txt")["id"]
    visits = _upload(api, folder, "bad.csv")["id"]
    evaluation = api.evaluate(_body(survey, estimate, visits=visits)).json()
    assert evaluation["status"] == "failed"
    assert evaluation["error"]["status"] == 422
    assert "'Q7'" in evaluation["error"]["detail"]
    assert str(tmp_path) not in evaluation["error"]["detail"]


def test_duplicate_ids_are_refused_at_upload(api: Api, tmp_path: Path) -> None:
    """A survey with a duplicate id is refused when uploaded, with the reader's message."""
    del tmp_path
    response = api.upload("survey.csv", b"id,x,y,z\nA,0,0,0\nB,1,0,0\nA,0,1,0\n")
    assert_problem(response, 422, detail=r"survey\.csv")


@pytest.mark.pdf
def test_a_schedule_evaluates_each_recording_against_a_fixed_survey(
    api: Api, rng: np.random.Generator, tmp_path: Path
) -> None:
    """A template whose reference names the survey's dataset scores every selected recording."""
    folder = tmp_path / "in"
    folder.mkdir()
    points = grid_points(3, 4)
    write_points(folder / "survey.csv", points)
    survey = _upload(api, folder, "survey.csv")["id"]
    expected = {}
    for k in range(2):
        rec = stop_and_go(rng, points, passes=1, bias_xyz=(0.01 * (k + 1), 0.0, 0.0))
        rows = estimate_tum_rows(rec)
        name = f"run{k}.txt"
        (folder / name).write_text("\n".join(rows) + "\n")
        api.dataset(name, (folder / name).read_bytes(), tags="floor")
        expected[name] = evaluate_checkpoints(points, rec.estimate).stats.rmse
    body = {
        "name": "Floor grid",
        "cron": "0 7 * * mon",
        "timezone": "UTC",
        "selection": {"tags": ["floor"]},
        "template": {
            "reference": {"dataset_id": survey, "name": "survey"},
            "estimates": [{"name": "slam"}],
            "options": {"align": "none"},
        },
    }
    created = api.client.post("/api/v1/schedules", json=body, headers=api.headers)
    assert created.status_code == 201, created.text
    url = f"/api/v1/schedules/{created.json()['id']}/run"
    run = api.client.post(url, headers=api.headers).json()
    assert run["status"] == "succeeded", run
    rows = {r["dataset"]: r for r in run["rows"]}
    assert set(rows) == set(expected)
    for name, rmse in expected.items():
        assert rows[name]["status"] == "succeeded", rows[name]
        assert rows[name]["summary"][0]["ate_rmse_m"] == pytest.approx(rmse, abs=1e-6)


def test_surveys_and_visits_are_not_estimates(
    api: Api, recording: StopAndGo, tmp_path: Path
) -> None:
    """A survey as an estimate, or a visits table as a source, is refused before queueing."""
    del recording
    folder = tmp_path / "in"
    survey = _upload(api, folder, "survey.csv")["id"]
    visits = _upload(api, folder, "visits.csv")["id"]
    assert_problem(
        api.evaluate(_body(survey, survey)),
        422,
        detail=r"The estimate dataset 'survey.csv' holds control points, not a trajectory",
    )
    assert_problem(
        api.evaluate(_body(visits, survey)),
        422,
        detail=r"The reference dataset 'visits.csv' is a visits table",
    )


@pytest.mark.usefixtures("recording")
def test_cad_files_and_hops(api: Api, tmp_path: Path) -> None:
    """The service serves the GLB and 3DM files; Hops returns the error lines of the JSON."""
    rhino3dm = pytest.importorskip("rhino3dm")
    folder = tmp_path / "in"
    survey = _upload(api, folder, "survey.csv")["id"]
    estimate = _upload(api, folder, "est.txt")["id"]
    body = _body(survey, estimate)
    body["options"]["formats"] = ["paths.3dm", "paths.3dm.json", "paths.glb"]
    evaluation = api.evaluate(body).json()
    assert evaluation["status"] == "succeeded", evaluation["error"]
    url = f"/api/v1/evaluations/{evaluation['id']}/artifacts"
    glb = api.client.get(f"{url}/paths.glb", headers=api.headers)
    assert glb.status_code == 200
    assert glb.content.startswith(b"glTF")
    assert api.client.get(f"{url}/paths.3dm", headers=api.headers).content.startswith(b"3D G")
    document = api.client.get(f"{url}/paths.3dm.json", headers=api.headers).json()
    values = [
        {"ParamName": name, "InnerTree": {"{0}": [{"type": "System.String", "data": data}]}}
        for name, data in (("Evaluation", f'"{evaluation["id"]}"'), ("Trajectory", '""'))
    ]
    solve = {"pointer": "hops/paths", "values": values, "warnings": [], "errors": []}
    response = api.client.post("/hops/paths", json=solve, headers={"RhinoComputeKey": api.key})
    assert response.status_code == 200, response.text
    (paths,) = [v["InnerTree"] for v in response.json()["values"] if v["ParamName"] == "Paths"]
    (items,) = paths.values()
    assert len(items) == len(document["paths"][0]["curves"]) == 24  # a line per visit
    curve = rhino3dm.CommonObject.Decode(json.loads(items[0]["data"]))
    assert curve.PointCount == 2
