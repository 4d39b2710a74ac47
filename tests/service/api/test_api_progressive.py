"""Progressive results: an evaluation's figures and files are served as each is written."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from service.jobs import executor as jobs
from tests.service import _job_hooks as hooks
from tests.service._api_fixtures import Api, assert_problem, tum_pair

WAIT_S = 60.0


def _pair_body(api: Api, rng: np.random.Generator, tmp_path: Path) -> dict[str, Any]:
    """An evaluation of an uploaded TUM pair writing result.json and errors.csv."""
    reference, estimate = tum_pair(rng, tmp_path)
    return {
        "reference": {"dataset_id": api.dataset("truth.txt", reference)["id"]},
        "estimates": [{"dataset_id": api.dataset("slam.txt", estimate)["id"]}],
        "options": {"formats": ["result.json", "errors.csv"]},
    }


def _release(api: Api, request: threading.Thread) -> None:
    """Let every held job go on (:func:`hooks.hold_after_result`) and wait for the request."""
    for folder in (api.data_dir / "evaluations").iterdir():
        (folder / hooks.HOLD_FILE).touch()
    request.join(WAIT_S)


def _running_with_result(api: Api) -> dict[str, Any]:
    """Poll the list, then the evaluation, until it runs and has its result document."""
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        items = api.client.get("/api/v1/evaluations", headers=api.headers).json()["items"]
        if items:
            url = f"/api/v1/evaluations/{items[0]['id']}"
            evaluation: dict[str, Any] = api.client.get(url, headers=api.headers).json()
            if evaluation["status"] != "queued" and evaluation["result"] is not None:
                return evaluation
        time.sleep(0.05)
    pytest.fail("the evaluation never showed its result while running")


def test_result_is_served_while_the_files_are_written(
    api: Api, rng: np.random.Generator, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """result.json is listed, shown and downloadable while the other files are still to come."""
    monkeypatch.setattr(jobs, "run_job", hooks.hold_after_result)
    body = _pair_body(api, rng, tmp_path)
    posted: list[Any] = []
    request = threading.Thread(target=lambda: posted.append(api.evaluate(body)))
    request.start()  # the immediate queue runs the job inside this request
    try:
        running = _running_with_result(api)
    finally:
        _release(api, request)

    assert running["status"] == "running"
    assert [a["name"] for a in running["artifacts"]] == ["result.json"]
    [estimate_row] = running["summary"]
    assert (
        estimate_row["ate_rmse_m"]
        == running["result"]["estimates"][0]["ate"]["translation_m"]["rmse"]
    )
    url = f"/api/v1/evaluations/{running['id']}/artifacts"
    served = api.client.get(f"{url}/result.json", headers=api.headers)
    assert served.status_code == 200
    assert served.json()["estimates"] == running["result"]["estimates"]
    assert (
        served.content
        == (api.data_dir / "evaluations" / running["id"] / "artifacts" / "result.json").read_bytes()
    )

    [response] = posted
    assert response.status_code == 202
    finished = api.client.get(f"/api/v1/evaluations/{running['id']}", headers=api.headers).json()
    assert finished["status"] == "succeeded"
    assert [a["name"] for a in finished["artifacts"]] == ["result.json", "errors.csv"]
    assert finished["result"]["estimates"] == running["result"]["estimates"]
    csv = api.client.get(f"{url}/errors.csv", headers=api.headers)
    assert csv.status_code == 200
    artifacts_dir = api.data_dir / "evaluations" / running["id"] / "artifacts"
    assert csv.content == (artifacts_dir / "errors.csv").read_bytes()
    assert sorted(p.name for p in artifacts_dir.iterdir()) == ["errors.csv", "result.json"]


def test_a_file_not_yet_written_is_409_naming_it(
    api: Api, rng: np.random.Generator, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """While an evaluation runs, a file it has not written yet is a 409 that names it."""
    monkeypatch.setattr(jobs, "run_job", hooks.hold_after_result)
    body = _pair_body(api, rng, tmp_path)
    request = threading.Thread(target=api.evaluate, args=(body,))
    request.start()
    try:
        running = _running_with_result(api)
        url = f"/api/v1/evaluations/{running['id']}/artifacts/errors.csv"
        response = api.client.get(url, headers=api.headers)
    finally:
        _release(api, request)
    assert_problem(
        response,
        409,
        detail=r"is running and has not written 'errors.csv' yet; poll GET /evaluations/\{id\}",
    )


def test_a_failed_evaluation_keeps_nothing_it_published(
    api: Api, rng: np.random.Generator, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A failure after result.json was published leaves no result, file or listing behind."""
    monkeypatch.setattr(jobs, "run_job", hooks.fail_after_result)
    body = _pair_body(api, rng, tmp_path)
    evaluation_id = api.evaluate(body).json()["id"]
    failed = api.client.get(f"/api/v1/evaluations/{evaluation_id}", headers=api.headers).json()
    assert failed["status"] == "failed"
    assert failed["error"]["detail"] == "The floor plan is unreadable; upload it again."
    assert (failed["result"], failed["summary"], failed["artifacts"]) == (None, None, None)
    assert not (api.data_dir / "evaluations" / evaluation_id / "artifacts").exists()
    url = f"/api/v1/evaluations/{evaluation_id}/artifacts/result.json"
    assert_problem(
        api.client.get(url, headers=api.headers), 409, detail=r"is failed, so it has no artifacts"
    )
