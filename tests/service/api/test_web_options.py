"""The browser page offers what the API offers: verdict, device offset, site, files, schedules.

Real Chromium (Playwright, the system package) against a real ``loceval serve``; the
fixtures ``browser`` and ``page`` are those of test_web_browser.py. Screenshots of the
options and of the schedules view are left in the test's tmp_path.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

from exporters import ARTIFACTS
from tests.factories import ROVER_URDF
from tests.service.api.test_web_browser import (
    ESTIMATE,
    EVALUATION_TIMEOUT_MS,
    GROUNDTRUTH,
    _choose,
    _enter_key,
    browser,
    page,
    refuse_option,
    wait_until_succeeded,
)
from tests.service.conftest import upload

__all__ = ["browser", "page"]  # the fixtures, used by name

pytestmark = [pytest.mark.slow, pytest.mark.public_data]

KEPT_FILES = [
    "result.json",
    "errors.csv",
    "map_cells.csv",
    "report.html",
    "paths.dxf",
    "viewer.html",
    "junit.xml",
    "summary.md",
]


def _open(page: Any, server: Any) -> None:
    """Open the page with the project's key; wait until the datasets are listed."""
    from playwright.sync_api import expect

    page.goto(f"{server.url}/")
    _enter_key(page, server.api_key)
    expect(page.locator("#app")).to_be_visible()
    expect(page.locator("#datasets-body tr", has_text=GROUNDTRUTH)).to_have_count(1)


@pytest.fixture
def uploaded(live_server: Any, public_data: Path, tmp_path: Path) -> dict[str, str]:
    """The TUM pair and a URDF uploaded through the API; their dataset ids by file name."""
    urdf = tmp_path / "rover.urdf"
    urdf.write_text(ROVER_URDF, encoding="utf-8")
    with live_server.client() as client:
        return {
            path.name: upload(client, path)["id"]
            for path in (public_data / GROUNDTRUTH, public_data / ESTIMATE, urdf)
        }


def _api(server: Any, method: str, path: str, **kwargs: Any) -> Any:
    with server.client() as client:
        answer = client.request(method, f"/api/v1{path}", **kwargs)
    answer.raise_for_status()
    return answer.json()


def test_every_api_option_is_sent(
    page: Any, live_server: Any, uploaded: dict[str, str], tmp_path: Path
) -> None:
    """Thresholds, tolerance, device offset from a URDF, site, simplify, files: sent as typed."""
    from playwright.sync_api import expect

    _open(page, live_server)
    _choose(page.locator("#reference-select"), GROUNDTRUTH)
    _choose(page.locator(".estimate-select").first, ESTIMATE)
    page.fill("#opt-tolerance", "0.10@95")
    for section in ("#verdict-options", "#device-options", "#cad-options"):
        page.click(f"{section} > summary")
    page.fill("#opt-thresholds", "0.05, 0.2")
    page.fill("#opt-worst", "5")
    _choose(page.locator("#opt-device-dataset"), "rover.urdf")
    links = page.locator("#device-links option")
    expect(links).to_have_count(2)
    assert sorted(links.evaluate_all("os => os.map(o => o.value)")) == [
        "camera_link",
        "rigid_body",
    ]
    page.fill("#opt-device-from", "rigid_body")
    page.fill("#opt-device-to", "camera_link")
    page.fill("#opt-site", "12.5  3.2 0 90")
    page.fill("#opt-simplify", "0.01")
    boxes = page.locator("#format-boxes input")
    expect(boxes).to_have_count(len(ARTIFACTS))  # the server's list, paths.ifc among them
    assert page.is_disabled("#format-boxes input[value='result.json']")
    for name in ("report.pdf", "paths.3dm", "paths.3dm.json", "paths.glb", "paths.ifc"):
        page.uncheck(f"#format-boxes input[value='{name}']")
    page.screenshot(path=str(tmp_path / "options.png"), full_page=True)

    page.click("#start-button")
    evaluation = _api(live_server, "GET", f"/evaluations/{wait_until_succeeded(page)}")
    options = evaluation["options"]
    assert options["tolerance"] == "0.10@95"
    assert options["thresholds_m"] == [0.05, 0.2]
    assert options["worst"] == 5
    assert options["device"] == {
        "dataset_id": uploaded["rover.urdf"],
        "from_link": "rigid_body",
        "to_link": "camera_link",
    }
    assert options["site"] == "12.5 3.2 0 90"
    assert options["simplify_m"] == 0.01
    assert sorted(options["formats"]) == sorted(KEPT_FILES)
    assert sorted(a["name"] for a in evaluation["artifacts"]) == sorted(KEPT_FILES)
    (estimate,) = evaluation["result"]["estimates"]
    assert sorted(estimate["within"]) == ["0.05", "0.2"]
    assert len(estimate["worst"]) == 5


@pytest.mark.usefixtures("uploaded")
def test_messages_name_the_pages_fields(page: Any, live_server: Any, tmp_path: Path) -> None:
    """A refused option is named by its field on the page (never options.KEY) and marked."""
    from playwright.sync_api import expect

    _open(page, live_server)
    _choose(page.locator("#reference-select"), GROUNDTRUTH)
    _choose(page.locator(".estimate-select").first, ESTIMATE)
    error = page.locator("#eval-form-error")
    form = {"start": "#start-button", "error": error}

    # The server's bounds (pydantic): the time offset is at most 1e9 s.
    page.click(".more-options > summary >> text=More options")
    refuse_option(
        page, "#opt-time-offset", "1e12", **form, option="time_offset_s", says=["“Time offset”"]
    )
    page.fill("#opt-time-offset", "")

    # The core's check (a problem with "option": "options.tolerance").
    refuse_option(
        page,
        "#opt-tolerance",
        "0.10@200",
        **form,
        option="tolerance",
        says=["“Tolerance”", "percent"],
    )
    page.locator("#evaluate-card").screenshot(path=str(tmp_path / "field_error.png"))
    page.fill("#opt-tolerance", "")

    # Two ways of one thing: the site transform and the matrix; the section opens itself.
    page.click("#cad-options > summary")
    page.fill("#opt-site", "1 2 3 4")
    page.fill("#opt-site-matrix", "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1")
    page.click("#start-button")
    expect(error).to_contain_text("site")
    expect(error).not_to_contain_text("options.")

    # Checked on the page before anything is sent.
    page.fill("#opt-site", "")
    page.fill("#opt-site-matrix", "1 0 0\n0 1 0")
    page.click("#start-button")
    expect(error).to_have_text("Site matrix: write 4 rows of 4 numbers, one row per line.")
    expect(page.locator("[data-option='site_matrix']")).to_have_class(re.compile("invalid"))
    assert _api(live_server, "GET", "/evaluations")["count"] == 0


@pytest.mark.pdf  # a schedule made on the page writes both summaries, summary.pdf among them
def test_schedules_view(page: Any, live_server: Any, public_data: Path, tmp_path: Path) -> None:
    """Create a schedule on the page, pause and resume it, run it now, open its summary."""
    from playwright.sync_api import expect

    with live_server.client() as client:
        for name in (GROUNDTRUTH, ESTIMATE):
            upload(client, public_data / name, tags="floor2")
    _open(page, live_server)
    expect(page.locator("#schedules-empty")).to_be_visible()
    page.click("#schedule-create > summary")
    page.fill("#sched-name", "Weekly floor 2")
    page.fill("#sched-cron", "0 7 * * mon")
    page.fill("#sched-timezone", "Europe/Berlin")
    page.fill("#sched-tags", "floor2")
    page.fill("#sched-estimate-name", "SLAM")
    page.fill("#opt-tolerance", "0.10@95")
    page.click("#schedule-create-button")
    row = page.locator("#schedules-body tr", has_text="Weekly floor 2")
    expect(row).to_have_count(1)
    expect(row).to_contain_text("0 7 * * mon")
    expect(row).to_contain_text("Europe/Berlin")
    expect(row).to_contain_text("tagged floor2")
    expect(row).to_contain_text("never run")
    (schedule,) = _api(live_server, "GET", "/schedules")["items"]
    assert schedule["template"]["options"]["tolerance"] == "0.10@95"
    assert schedule["template"]["estimates"] == [
        {"selector": None, "name": "SLAM", "dataset_id": None}
    ]

    row.get_by_role("button", name="Pause").click()
    expect(row).to_have_attribute("data-paused", "true")
    expect(row).to_contain_text("does not fire while paused")
    assert _api(live_server, "GET", f"/schedules/{schedule['id']}")["paused"] is True
    row.get_by_role("button", name="Resume").click()
    expect(row).to_have_attribute("data-paused", "false")
    expect(row).to_contain_text("next:")

    row.get_by_role("button", name="Run now").click()
    open_summary = row.get_by_role("button", name="Open summary")
    expect(open_summary).to_be_visible(timeout=EVALUATION_TIMEOUT_MS)
    expect(row.locator(".last-run")).to_contain_text("Succeeded")
    expect(row.locator(".last-run")).to_contain_text("2 recordings")
    page.screenshot(path=str(tmp_path / "schedules.png"), full_page=True)
    with page.expect_popup() as popup_info:
        open_summary.click()
    summary = popup_info.value
    summary.wait_for_url(re.compile(r"^blob:"), timeout=30_000)
    summary.wait_for_load_state()
    assert "Weekly floor 2" in summary.content()
    summary.close()
