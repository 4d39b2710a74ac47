"""Every hostile case through the HTTP API: upload it, then evaluate with it (immediate jobs).

The contract: no answer is a 5xx; a 4xx is an ``application/problem+json`` document with a
message; no answer names a server folder (the data folder, a temporary folder); a job that
fails carries a user-facing reason (a problem whose type is not ``internal``). Valid inputs
upload with 201 and their evaluation succeeds.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.hostile.bases import (
    ANCHORS,
    CP_ESTIMATE,
    CP_SURVEY,
    ESTIMATE,
    RANGES,
    WALK,
    Role,
    write_companions,
)
from tests.hostile.corpus import CASES, Case
from tests.hostile.run import CHEAP, assert_clean_text, params, upload_payload
from tests.service._api_fixtures import PROBLEM_JSON, Api, open_api

pytestmark = pytest.mark.slow


class Site:
    """The module's app, with the valid companion files uploaded once per role."""

    def __init__(self, api: Api, folder: Path) -> None:
        """Use ``api``; write companions under ``folder``."""
        self.api = api
        self.folder = folder
        self._ids: dict[str, str] = {}

    def companion(self, role: Role, name: str) -> str:
        """Return the dataset id of a valid companion file of ``role``."""
        key = f"{role}/{name}"
        if key not in self._ids:
            folder = self.folder / str(role)
            if not folder.is_dir():
                folder.mkdir(parents=True)
                write_companions(folder, role)
            response = self.api.upload(name, (folder / name).read_bytes())
            assert response.status_code in {200, 201}, response.text
            self._ids[key] = response.json()["id"]
        return self._ids[key]


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Site]:
    """One app for the module (immediate jobs); the cases upload distinct files."""
    tmp_path = tmp_path_factory.mktemp("hostile-http")
    with open_api(tmp_path, raise_server_exceptions=False) as api:
        yield Site(api, tmp_path / "companions")


def _checked(response: Any, *folders: Path) -> Any:
    """Assert the answer is no 5xx, a 4xx is a problem document, and no folder is named."""
    assert response.status_code < 500, response.text[:3000]
    assert_clean_text(response.text, *folders)
    if response.status_code >= 400:
        assert response.headers["content-type"].split(";")[0] == PROBLEM_JSON, response.text
        body = response.json()
        assert body["status"] == response.status_code
        assert isinstance(body["detail"], str)
        assert len(body["detail"]) > 10, body
    return response


def _request(site: Site, case: Case, dataset_id: str) -> tuple[str, dict[str, Any]] | None:
    """Return the endpoint and body that evaluate with the uploaded input, or None."""
    role = case.base.role
    options = {**CHEAP, **case.options}
    if role is Role.TRAJECTORY:
        estimate = site.companion(role, ESTIMATE)
        selector = case.base.selector[1:]  # KITTI's times file is a CLI option: none here
        reference = {
            "dataset_id": dataset_id,
            "selector": None if "=" in selector else selector or None,
        }
        body = {"reference": reference, "estimates": [{"dataset_id": estimate}]}
        return "/api/v1/evaluations", {**body, "options": options}
    if role in {Role.POINTS, Role.VISITS}:
        estimate = site.companion(role, CP_ESTIMATE)
        survey = dataset_id if role is Role.POINTS else site.companion(role, CP_SURVEY)
        if role is Role.VISITS:
            options["visits"] = dataset_id
        body = {"reference": {"dataset_id": survey}, "estimates": [{"dataset_id": estimate}]}
        return "/api/v1/evaluations", {**body, "options": {**options, "align": "none"}}
    if role in {Role.ANCHORS, Role.RANGES}:
        anchors = dataset_id if role is Role.ANCHORS else site.companion(role, ANCHORS)
        ranges = dataset_id if role is Role.RANGES else site.companion(role, RANGES)
        reference = {"dataset_id": site.companion(role, WALK)}
        return "/api/v1/ranging", {
            "reference": reference,
            "anchors": anchors,
            "ranges": ranges,
            "options": options,
        }
    return None  # a building model is an export input of the CLI: the upload is the test


@pytest.mark.parametrize("case", params(CASES, "http"))
def test_http_hostile_input(site: Site, case: Case, tmp_path: Path) -> None:
    """Upload and evaluation answer 4xx problems or succeed; failed jobs say why."""
    folder = tmp_path / "case"
    folder.mkdir()
    write_companions(folder, case.base.role)
    name, content = upload_payload(case.build(folder))
    api = site.api
    folders = (tmp_path, api.data_dir)
    uploaded = _checked(api.upload(name, content), *folders)
    valid = case.valid and case.base.name != "kitti"  # without times: frame-index stamps
    if valid:
        assert uploaded.status_code in {200, 201}, uploaded.text
    if uploaded.status_code >= 400:
        return
    request = _request(site, case, uploaded.json()["id"])
    if request is None:
        return
    endpoint, body = request
    response = _checked(api.client.post(endpoint, headers=api.headers, json=body), *folders)
    if valid:
        assert response.status_code == 202, response.text
    if response.status_code >= 400:
        return
    evaluation = response.json()
    assert evaluation["status"] in {"succeeded", "failed"}, evaluation
    if valid:
        assert evaluation["status"] == "succeeded", evaluation["error"]
    if evaluation["status"] == "failed":
        error = evaluation["error"]
        assert error["type"] != "internal", json.dumps(error)[:2000]
        assert len(error["detail"]) > 10, error
