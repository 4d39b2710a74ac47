"""The Grasshopper Hops endpoint: what Rhino's Hops client sends and reads back."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.service._api_fixtures import Api, bearer, tum_pair

ezdxf = pytest.importorskip("ezdxf")
rhino3dm = pytest.importorskip("rhino3dm")

FORMATS = {"formats": ["paths.3dm.json", "paths.dxf"]}


@pytest.fixture
def evaluation(api: Api, rng: np.random.Generator, tmp_path: Path) -> dict[str, Any]:
    """A succeeded evaluation of a TUM pair that wrote the 3DM JSON and the DXF."""
    reference, estimate = tum_pair(rng, tmp_path)
    ref = api.dataset("truth.txt", reference)["id"]
    est = api.dataset("slam.txt", estimate)["id"]
    body = {
        "reference": {"dataset_id": ref},
        "estimates": [{"dataset_id": est}],
        "options": FORMATS,
    }
    document: dict[str, Any] = api.evaluate(body).json()
    assert document["status"] == "succeeded", document
    return document


def solve_body(
    evaluation_id: str, trajectory: str = "", *, pointer: str = "hops/paths"
) -> dict[str, Any]:
    """Return a solve request as Rhino 8's Hops client posts it (strings JSON-encoded)."""
    return {
        "absolutetolerance": 0.001,
        "angletolerance": 1.0,
        "modelunits": "Millimeters",
        "dataversion": 8,
        "algo": None,
        "pointer": pointer,
        "cachesolve": False,
        "recursionlevel": 0,
        "values": [
            {
                "ParamName": "Evaluation",
                "InnerTree": {
                    "{0}": [{"type": "System.String", "data": json.dumps(evaluation_id)}]
                },
            },
            {
                "ParamName": "Trajectory",
                "InnerTree": {"{0}": [{"type": "System.String", "data": json.dumps(trajectory)}]},
            },
        ],
        "warnings": [],
        "errors": [],
    }


def output(document: dict[str, Any], name: str) -> dict[str, list[dict[str, str]]]:
    """Return one output's data tree."""
    (value,) = [v for v in document["values"] if v["ParamName"] == name]
    tree: dict[str, list[dict[str, str]]] = value["InnerTree"]
    return tree


def hops_key(api: Api) -> dict[str, str]:
    """The header Hops sends with the API key of its preferences."""
    return {"RhinoComputeKey": api.key}


def test_lists_and_describes_components(api: Api) -> None:
    """GET /hops/ lists the components; GET /hops/paths describes inputs and outputs."""
    listed = api.client.get("/hops/")
    assert listed.status_code == 200
    assert [c["Uri"] for c in listed.json()] == ["/hops/paths"]
    component = api.client.get("/hops/paths").json()
    assert component["Name"] == "loceval paths"
    assert [(p["Name"], p["ParamType"], p["AtMost"]) for p in component["Inputs"]] == [
        ("Evaluation", "Text", 1),
        ("Trajectory", "Text", 1),
    ]
    outputs = {p["Name"]: p["ResultType"] for p in component["Outputs"]}
    assert outputs["Paths"] == "Rhino.Geometry.Curve"
    assert outputs["ATE"] == "System.Double"
    unknown = api.client.get("/hops/nothing")
    assert unknown.status_code == 404
    assert "No Hops component 'nothing'" in unknown.json()["detail"]


@pytest.mark.parametrize("route", ["/solve", "/hops/solve", "/hops/paths"])
def test_solve_returns_the_dxf_polylines(api: Api, evaluation: dict[str, Any], route: str) -> None:
    """A solve returns one branch per trajectory whose curve is the DXF polyline within 1 mm."""
    response = api.client.post(route, json=solve_body(evaluation["id"]), headers=hops_key(api))
    assert response.status_code == 200, response.text
    document = response.json()
    assert document["errors"] == []
    assert document["warnings"] == []
    names = {k: json.loads(v[0]["data"]) for k, v in output(document, "Names").items()}
    assert names == {"{0}": "truth", "{1}": "slam"}
    url = f"/api/v1/evaluations/{evaluation['id']}/artifacts/paths.dxf"
    dxf = ezdxf.read(io.StringIO(api.client.get(url, headers=api.headers).text))
    for branch, items in output(document, "Paths").items():
        # one curve per continuous piece, as the DXF has one POLYLINE per piece
        polylines = dxf.modelspace().query(f'POLYLINE[layer=="{names[branch]}"]')
        assert len(items) == len(polylines) >= 1
        for item, polyline in zip(items, polylines, strict=True):
            assert item["type"] == "Rhino.Geometry.PolylineCurve"
            curve = rhino3dm.CommonObject.Decode(json.loads(item["data"]))
            points = np.array(
                [[p.X, p.Y, p.Z] for p in (curve.Point(i) for i in range(curve.PointCount))]
            )
            expected = np.array([v.dxf.location.xyz for v in polyline.vertices])
            assert points.shape == expected.shape
            assert np.abs(points - expected).max() <= 1.0  # millimetres
    colours = {k: json.loads(v[0]["data"]) for k, v in output(document, "Colours").items()}
    assert colours == {"{0}": "0,255,255", "{1}": "255,0,255"}  # the palette: cyan, magenta
    ate = output(document, "ATE")
    assert ate["{0}"] == []
    result = api.client.get(
        f"/api/v1/evaluations/{evaluation['id']}/artifacts/result.json", headers=api.headers
    ).json()
    expected_rmse = result["estimates"][0]["ate"]["translation_m"]["rmse"]
    assert float(ate["{1}"][0]["data"]) == expected_rmse
    # the estimate's runs in the one error colour scale, as paths.3dm.json has them
    runs = output(document, "ATE paths")
    colours = output(document, "ATE colours")
    assert runs["{0}"] == colours["{0}"] == []
    assert len(runs["{1}"]) == len(colours["{1}"]) >= 1
    assert all(item["type"] == "Rhino.Geometry.PolylineCurve" for item in runs["{1}"])
    scale = {",".join(map(str, b["color"])) for b in result_bins(api, evaluation)}
    assert {json.loads(item["data"]) for item in colours["{1}"]} <= scale
    statistics = json.loads(json.loads(output(document, "Statistics")["{1}"][0]["data"]))
    assert statistics["kind"] == "estimate"
    assert (
        statistics["ate_legend"].startswith("ATE colours")
        or "Tolerance" in statistics["ate_legend"]
    )
    assert (
        statistics["rpe"]["translation_m"]["rmse"]
        == result["estimates"][0]["rpe"]["translation_m"]["rmse"]
    )


def result_bins(api: Api, evaluation: dict[str, Any]) -> list[dict[str, Any]]:
    """The colour bins of the evaluation's paths.3dm.json."""
    url = f"/api/v1/evaluations/{evaluation['id']}/artifacts/paths.3dm.json"
    bins: list[dict[str, Any]] = api.client.get(url, headers=api.headers).json()["ate_bins"]
    return bins


def test_one_trajectory_and_unit_warning(api: Api, evaluation: dict[str, Any]) -> None:
    """A trajectory name picks one path; a document in other units gets a warning."""
    body = solve_body(evaluation["id"], "slam", pointer="/hops/paths")
    body["modelunits"] = "Meters"
    document = api.client.post("/solve", json=body, headers=hops_key(api)).json()
    assert list(output(document, "Paths")) == ["{0}"]
    assert json.loads(output(document, "Names")["{0}"][0]["data"]) == "slam"
    assert document["warnings"] == [
        (
            "The paths are in Millimeters (the evaluation's units) and this document is in "
            "Meters; scale them or evaluate with matching units."
        )
    ]


def test_bearer_key_works_too(api: Api, evaluation: dict[str, Any]) -> None:
    """A client that sends Authorization: Bearer instead of RhinoComputeKey is accepted."""
    response = api.client.post("/solve", json=solve_body(evaluation["id"]), headers=bearer(api.key))
    assert response.status_code == 200


def test_missing_or_unknown_key(api: Api, evaluation: dict[str, Any]) -> None:
    """No key, or an unknown one, is 401 with what to do."""
    response = api.client.post("/solve", json=solve_body(evaluation["id"]))
    assert response.status_code == 401
    assert "RhinoComputeKey" in response.json()["detail"]
    response = api.client.post(
        "/solve", json=solve_body(evaluation["id"]), headers={"RhinoComputeKey": "lk_nope"}
    )
    assert response.status_code == 401
    assert "unknown or revoked" in response.json()["detail"]


@pytest.mark.parametrize(
    ("evaluation_id", "trajectory", "status", "match"),
    [
        ("", "", 422, "The Evaluation input is empty"),
        ("nope", "", 404, "No evaluation 'nope' in this project"),
        (None, "ghost", 422, "has no trajectory 'ghost'; its trajectories are 'truth', 'slam'"),
    ],
)
def test_errors_in_the_protocol(  # noqa: PLR0917  (pytest passes parameters by name)
    api: Api,
    evaluation: dict[str, Any],
    evaluation_id: str | None,
    trajectory: str,
    status: int,
    match: str,
) -> None:
    """Domain errors come back in the protocol's errors list, which the component shows."""
    chosen = evaluation["id"] if evaluation_id is None else evaluation_id
    response = api.client.post("/solve", json=solve_body(chosen, trajectory), headers=hops_key(api))
    assert response.status_code == status
    document = response.json()
    assert document["values"] == []
    (error,) = document["errors"]
    assert match in error


def test_other_projects_evaluation_is_not_found(api: Api, evaluation: dict[str, Any]) -> None:
    """Another project's key cannot read the paths."""
    response = api.client.post(
        "/solve", json=solve_body(evaluation["id"]), headers={"RhinoComputeKey": api.other_key}
    )
    assert response.status_code == 404
    assert "No evaluation" in response.json()["errors"][0]


def test_evaluation_without_cad_files(api: Api, rng: np.random.Generator, tmp_path: Path) -> None:
    """An evaluation that did not write paths.3dm.json says to run it with the CAD files."""
    reference, estimate = tum_pair(rng, tmp_path)
    body = {
        "reference": {"dataset_id": api.dataset("truth.txt", reference)["id"]},
        "estimates": [{"dataset_id": api.dataset("slam.txt", estimate)["id"]}],
        "options": {"formats": ["result.json"]},
    }
    evaluation = api.evaluate(body).json()
    response = api.client.post("/solve", json=solve_body(evaluation["id"]), headers=hops_key(api))
    assert response.status_code == 404
    assert "did not write 'paths.3dm.json'" in response.json()["errors"][0]
