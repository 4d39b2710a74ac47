"""Building models as uploads: inspected once, then named by id in an evaluation's options."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from tests.factories import make_trajectory, write_tum
from tests.service._api_fixtures import Api, assert_problem

ezdxf = pytest.importorskip("ezdxf")
pytest.importorskip("ifcopenshell")
from tests.exporters.ifcfactory import GRID_CONVERSION, write_room  # noqa: E402  (needs ifcopenshell)


def _pair(tmp_path: Path, rng: np.random.Generator) -> tuple[bytes, bytes]:
    truth = make_trajectory(rng, 400)
    ref = write_tum(tmp_path / "ref.txt", truth)
    return ref.read_bytes(), ref.read_bytes()


def test_ifc_upload_is_a_georeferenced_building(api: Api, tmp_path: Path) -> None:
    """An IFC upload is kind building, with its CRS and no trajectory sources."""
    room = write_room(tmp_path / "room.ifc", map_conversion=GRID_CONVERSION)
    dataset = api.dataset("room.ifc", room.read_bytes())
    assert dataset["kind"] == "building"
    inspection = dataset["inspection"]
    assert inspection["format"] == "ifc"
    assert inspection["georeferenced"] is True
    assert inspection["crs"] == "EPSG:25832"
    assert inspection["faces"] > 0
    assert inspection["sources"] == []


def test_broken_building_is_refused_at_upload(api: Api) -> None:
    """A file named .ifc that is not IFC is a 422 naming the upload, not a server path."""
    response = api.upload("model.ifc", b"ISO-10303-21;\nthis is not a model\n")
    problem = assert_problem(response, 422, detail="model.ifc")
    assert str(api.data_dir) not in problem["detail"]


def test_evaluation_places_paths_by_the_ifc_georeference(
    api: Api, tmp_path: Path, rng: np.random.Generator
) -> None:
    """With options.building an IFC, the DXF lands on the IFC's map coordinates."""
    room = api.dataset(
        "room.ifc", write_room(tmp_path / "r.ifc", map_conversion=GRID_CONVERSION).read_bytes()
    )
    ref, est = _pair(tmp_path, rng)
    ref_id = api.dataset("ref.txt", ref)["id"]
    est_id = api.dataset("est.txt", est + b"\n")["id"]
    body = {
        "reference": {"dataset_id": ref_id},
        "estimates": [{"dataset_id": est_id}],
        "options": {"building": room["id"], "units": "m", "formats": ["dxf", "json"]},
    }
    response = api.evaluate(body)
    assert response.status_code == 202, response.text
    evaluation = api.client.get(
        f"/api/v1/evaluations/{response.json()['id']}", headers=api.headers
    ).json()
    assert evaluation["status"] == "succeeded", evaluation.get("error")
    url = f"/api/v1/evaluations/{evaluation['id']}/artifacts/paths.dxf"
    doc = ezdxf.read(io.StringIO(api.client.get(url, headers=api.headers).text))
    xyz = np.array(
        [v.dxf.location.xyz for p in doc.modelspace().query("POLYLINE") for v in p.vertices]
    )
    # the trajectory is a few metres across: placed, it sits by the IFC's map origin
    assert np.abs(xyz[:, 0] - GRID_CONVERSION["Eastings"]).max() < 100.0
    assert np.abs(xyz[:, 1] - GRID_CONVERSION["Northings"]).max() < 100.0


def test_building_option_must_name_a_building(
    api: Api, tmp_path: Path, rng: np.random.Generator
) -> None:
    """A trajectory dataset given as the building is a 422 on options.building."""
    ref, _ = _pair(tmp_path, rng)
    ref_id = api.dataset("ref.txt", ref)["id"]
    body = {
        "reference": {"dataset_id": ref_id},
        "estimates": [{"dataset_id": ref_id}],
        "options": {"building": ref_id},
    }
    problem = assert_problem(api.evaluate(body), 422, detail="not a building model")
    assert problem["option"] == "options.building"
