"""options.map over the API: a map zip or a bag topic measured against an uploaded plan."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.service._api_fixtures import Api, assert_problem
from tests.service.cli.test_cli_map import _recording as _recording  # noqa: PLC0414  (the fixture)

pytest.importorskip("ezdxf")


def _datasets(api: Api, recording: dict[str, Path]) -> dict[str, str]:
    return {
        name: api.dataset(recording[name].name, recording[name].read_bytes())["id"]
        for name in ("reference", "estimate", "zip", "dxf")
    }


def test_a_map_zip_is_measured_against_the_plan(api: Api, recording: dict[str, Path]) -> None:
    """A map zip upload is kind map; options.map (a bare id) puts ``map`` into the result."""
    ids = _datasets(api, recording)
    dataset = api.client.get(f"/api/v1/datasets/{ids['zip']}", headers=api.headers).json()
    assert dataset["kind"] == "map"
    assert dataset["inspection"]["map"]["resolution_m"] == pytest.approx(0.05)
    body = {
        "reference": {"dataset_id": ids["reference"]},
        "estimates": [{"dataset_id": ids["estimate"], "name": "SLAM"}],
        "options": {
            "building": ids["dxf"],
            "map": ids["zip"],
            "no_ci": True,
            "formats": ["json"],
        },
    }
    response = api.evaluate(body)
    assert response.status_code == 202, response.text
    evaluation = api.client.get(
        f"/api/v1/evaluations/{response.json()['id']}", headers=api.headers
    ).json()
    assert evaluation["status"] == "succeeded", evaluation.get("error")
    found = evaluation["result"]["map"]
    assert found["source"] == "map.zip"
    assert found["wall_distance_m"]["rmse"] < 0.025
    assert found["plan_coverage"] > 0.95
    assert set(found["fit"]) == {"rigid", "similarity"}


@pytest.mark.parametrize(
    ("options", "status", "detail"),
    [
        ({"map": "DATASET"}, 422, "give options.building too"),
        ({"map": {"dataset_id": "PLAN"}, "building": "PLAN"}, 422, "is not a map"),
        ({"map": {"dataset_id": "nope"}}, 404, "nope"),
        ({"clutter_m": 0}, 422, "clutter_m"),
    ],
)
def test_bad_map_options_are_4xx(
    api: Api, recording: dict[str, Path], options: dict[str, object], status: int, detail: str
) -> None:
    """A map without a plan, a plan given as the map, an unknown map, a zero clutter distance."""
    ids = _datasets(api, recording)
    names = {"DATASET": ids["zip"], "PLAN": ids["dxf"]}

    def named(value: object) -> object:
        if isinstance(value, dict):
            return {k: named(v) for k, v in value.items()}
        return names.get(value, value) if isinstance(value, str) else value

    body = {
        "reference": {"dataset_id": ids["reference"]},
        "estimates": [{"dataset_id": ids["estimate"]}],
        "options": named(options),
    }
    response = api.evaluate(body)
    assert_problem(response, status, detail=detail)
