"""What the page shows of an evaluation reads right: verdicts, progress, card numbers, files.

Real Chromium (Playwright, the system package) against a real ``loceval serve``; the
fixtures ``browser`` and ``page`` are those of test_web_browser.py. Screenshots are left in
the test's tmp_path.
"""

from __future__ import annotations

import json
import re
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from exporters import ARTIFACTS
from exporters.cad.site import BUILDING_SUFFIXES
from tests.factories import make_trajectory, perturb, write_tum
from tests.service.api.test_web_browser import (
    _choose,
    _enter_key,
    browser,
    page,
    wait_until_succeeded,
)
from tests.service.conftest import submit, upload, wait_for_evaluation

__all__ = ["browser", "page"]  # the fixtures, used by name

pytestmark = [pytest.mark.slow]

NAV2 = "nav2_turtlebot.mcap"

# Records every text of the progress line with the card's status at that moment.
_WATCH_STAGE = """() => {
  window.stagesSeen = [];
  const stage = document.getElementById("current-stage");
  new MutationObserver(() => window.stagesSeen.push(
    [document.getElementById("current-card").dataset.status, stage.textContent]
  )).observe(stage, { childList: true, characterData: true, subtree: true });
}"""


def _open(page: Any, server: Any) -> None:
    from playwright.sync_api import expect

    page.goto(f"{server.url}/")
    _enter_key(page, server.api_key)
    expect(page.locator("#app")).to_be_visible()


def _shown_step_numbers(page: Any) -> list[str]:
    """The numbers of the cards a user sees, top to bottom."""
    numbers: list[str] = page.locator("#app > .card:not([hidden]) h2 .step").all_inner_texts()
    return numbers


def _only_files(page: Any, names: list[str]) -> None:
    """Tick only ``names`` under "Files to make" (result.json is always made)."""
    for box in page.locator("#format-boxes input:not([disabled])").all():
        if box.get_attribute("value") in names:
            box.check()
        else:
            box.uncheck()


@pytest.fixture(scope="module")
def nav2_evaluations(live_server_module: Any, public_data: Path) -> dict[str, str]:
    """Nav2's AMCL against tf:map:base_link, unaligned: at 0.10@95 (undecided) and without.

    Made through the API (result.json only); their ids by ``undecided`` and ``plain``.
    """
    with live_server_module.client() as client:
        nav2 = upload(client, public_data / NAV2)
        reference = {"dataset_id": nav2["id"], "selector": "tf:map:base_link"}
        ids = {}
        for key, extra in (("undecided", {"tolerance": "0.10@95"}), ("plain", {})):
            estimate = {"dataset_id": nav2["id"], "selector": "/amcl_pose", "name": "AMCL"}
            options = {"align": "none", "formats": ["result.json"], **extra}
            ids[key] = submit(client, reference, [estimate], options)["id"]
        for evaluation_id in ids.values():
            assert wait_for_evaluation(client, evaluation_id)["status"] == "succeeded"
    return ids


def _history_row(page: Any, evaluation_id: str) -> Any:
    return page.locator(f"#history-body tr[data-evaluation-id='{evaluation_id}']")


def _open_evaluation(page: Any, evaluation_id: str) -> None:
    from playwright.sync_api import expect

    _history_row(page, evaluation_id).get_by_role("button", name="Open").click()
    card = page.locator("#current-card")
    expect(card).to_have_attribute("data-evaluation-id", evaluation_id)
    expect(card).to_have_attribute("data-status", "succeeded")


@pytest.mark.public_data
def test_an_undecided_verdict_reads_as_the_report(
    page: Any, live_server_module: Any, nav2_evaluations: dict[str, str], tmp_path: Path
) -> None:
    """96.1 % within 0.10 m, interval 90.7-100 %: UNDECIDED with the interval, in both rows."""
    from playwright.sync_api import expect

    _open(page, live_server_module)
    evaluation_id = nav2_evaluations["undecided"]
    expect(_history_row(page, evaluation_id).locator(".verdict")).to_have_text("UNDECIDED")
    _open_evaluation(page, evaluation_id)
    verdict = page.locator("#summary-body td.verdict-cell")
    expect(verdict.locator(".verdict")).to_have_text("UNDECIDED")
    expect(verdict).to_contain_text("96.1 % within 0.1 m")
    expect(verdict).to_contain_text("95 % interval 90.7–100.0 %")
    expect(verdict).to_contain_text("95 % required")
    expect(verdict).not_to_contain_text("no tolerance")
    page.locator("#current-card").screenshot(path=str(tmp_path / "undecided.png"))


@pytest.mark.public_data
def test_no_tolerance_shows_no_null_in_the_history(
    page: Any, live_server_module: Any, nav2_evaluations: dict[str, str]
) -> None:
    """Without a tolerance the history's ATE cell is the figure alone: no badge, no null."""
    from playwright.sync_api import expect

    _open(page, live_server_module)
    row = _history_row(page, nav2_evaluations["plain"])
    expect(row).to_have_attribute("data-status", "succeeded")
    expect(row).not_to_contain_text("null")
    expect(row.locator(".verdict")).to_have_count(0)
    ate = row.locator("td[data-label='ATE RMSE']").inner_text().strip()
    # the one rule for lengths: metres to the mm, or mm to a tenth below 0.1 m
    assert re.fullmatch(r"\d+\.\d{3} m|\d+\.\d mm", ate), ate


@pytest.mark.public_data
def test_cards_are_numbered_one_by_one(
    page: Any, live_server_module: Any, nav2_evaluations: dict[str, str], tmp_path: Path
) -> None:
    """The shown cards read 1, 2, 3, ... in order, before and after an evaluation is opened."""
    _open(page, live_server_module)
    before = _shown_step_numbers(page)
    assert before == [str(k) for k in range(1, len(before) + 1)]
    _open_evaluation(page, nav2_evaluations["plain"])
    after = _shown_step_numbers(page)
    assert after == [str(k) for k in range(1, len(before) + 2)]
    page.screenshot(path=str(tmp_path / "page.png"), full_page=True)


SLOW_POSES = 300_000
"""Reference poses of the run the progress line is watched on (a quarter as many estimated):
with every file it takes several of the page's one-second polls on any machine, where
Nav2's bag with three files now finishes between two."""


def test_the_progress_line_says_what_a_running_job_does(
    page: Any, live_server_module: Any, tmp_path: Path, rng: np.random.Generator
) -> None:
    """Every text of the progress line while the job runs is "Stage… N%", never "Done"."""
    truth = make_trajectory(rng, SLOW_POSES, dt_ns=5_000_000)
    estimate = perturb(truth.select(np.arange(0, SLOW_POSES, 4)), rng, sigma_m=0.02)
    with live_server_module.client() as client:
        upload(client, write_tum(tmp_path / "long-run-reference.tum", truth))
        upload(client, write_tum(tmp_path / "long-run-estimate.tum", estimate))
    _open(page, live_server_module)
    _choose(page.locator("#reference-select"), "long-run-reference.tum")
    _choose(page.locator(".estimate-select").first, "long-run-estimate.tum")
    page.select_option("#opt-align", "none")
    page.evaluate(_WATCH_STAGE)
    page.click("#start-button")
    wait_until_succeeded(page)
    seen = page.evaluate("window.stagesSeen")
    running = [text for status, text in seen if status == "running"]
    assert running  # the page watched it run
    assert all(re.fullmatch(r"[A-Z][^…]*… \d+%", text) for text in running), running
    assert not [text for text in running if text.lower().startswith("done")], running


def test_files_to_make_are_the_servers_artifacts(page: Any, live_server_module: Any) -> None:
    """ "Files to make" has one box per artifact the server makes, paths.ifc among them."""
    from playwright.sync_api import expect

    _open(page, live_server_module)
    page.click("#cad-options > summary")
    boxes = page.locator("#format-boxes input")
    assert boxes.evaluate_all("bs => bs.map(b => b.value)") == list(ARTIFACTS)
    expect(page.locator("#format-boxes input[value='paths.ifc']")).to_be_checked()
    expect(page.locator("#format-boxes input[value='paths.ifc']")).to_be_enabled()


_BOX_OBJ = """# a 12 m x 8 m x 3 m room around the path
v -6 -4 0
v 6 -4 0
v 6 4 0
v -6 4 0
v -6 -4 3
v 6 -4 3
v 6 4 3
v -6 4 3
f 1 2 3
f 1 3 4
f 5 7 6
f 5 8 7
f 1 5 6
f 1 6 2
f 2 6 7
f 2 7 3
f 3 7 8
f 3 8 4
f 4 8 5
f 4 5 1
"""


def _glb_node_names(data: bytes) -> list[str]:
    """The node names of a binary glTF (its JSON chunk follows the 12-byte header)."""
    length, kind = struct.unpack_from("<I4s", data, 12)
    assert kind == b"JSON"
    document = json.loads(data[20 : 20 + length])
    return [node.get("name", "") for node in document["nodes"]]


def test_building_model_is_uploaded_and_picked_on_the_page(
    page: Any, live_server_module: Any, tmp_path: Path, rng: np.random.Generator
) -> None:
    """Upload an OBJ on the page, pick it, make paths.glb and paths.ifc: the scene has it."""
    from playwright.sync_api import expect

    truth = make_trajectory(rng, 400)
    ref = write_tum(tmp_path / "truth.txt", truth)
    est = write_tum(tmp_path / "slam.txt", truth, header=False)  # other bytes: no duplicate
    room = tmp_path / "room.obj"
    room.write_text(_BOX_OBJ, encoding="utf-8")
    _open(page, live_server_module)
    hint = page.locator("#upload-card .hint").first
    for suffix in BUILDING_SUFFIXES:
        expect(hint).to_contain_text(suffix.lstrip(".").upper())

    page.set_input_files("#file-input", [ref, est, room])
    done = page.locator("#upload-list li[data-state=done]")
    expect(done).to_have_count(3, timeout=60_000)
    expect(page.locator("#upload-list li", has_text="room.obj")).to_contain_text(
        "OBJ building model, 12 faces"
    )
    row = page.locator("#datasets-body tr", has_text="room.obj")
    expect(row).to_contain_text("building model")
    expect(row).not_to_contain_text("No trajectory found")
    room_id = row.get_attribute("data-dataset-id")

    _choose(page.locator("#reference-select"), "truth.txt")
    _choose(page.locator(".estimate-select").first, "slam.txt")
    page.click("#cad-options > summary")
    _choose(page.locator("#opt-building"), "room.obj")
    expect(page.locator("#opt-building-up option")).to_have_text(["format", "z", "y"])
    _only_files(page, ["paths.glb", "paths.ifc"])
    page.locator("#evaluate-card").screenshot(path=str(tmp_path / "building.png"))
    page.click("#start-button")
    evaluation_id = wait_until_succeeded(page)

    with live_server_module.client() as client:
        evaluation = client.get(f"/api/v1/evaluations/{evaluation_id}").json()
        assert evaluation["options"]["building"] == room_id
        assert evaluation["options"]["building_up"] == "format"  # the file's own convention
        names = sorted(a["name"] for a in evaluation["artifacts"])
        assert names == ["paths.glb", "paths.ifc", "result.json"]
        glb = client.get(f"/api/v1/evaluations/{evaluation_id}/artifacts/paths.glb").content
    assert "building" in _glb_node_names(glb)
    buttons = page.locator("#artifact-list button[data-artifact]")
    expect(buttons).to_have_count(3)
