"""The page shows an evaluation's gate (options.fail_on): closed with why, or passed.

Real Chromium (Playwright, the system package) against a real ``loceval serve``; the
fixtures ``browser`` and ``page`` are those of test_web_browser.py. The options field of
the gate is made from the options table ("Other options"); the screenshot is left in the
test's tmp_path.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.service.api.test_web_browser import _enter_key, browser, page
from tests.service.api.test_web_results import _history_row, _open_evaluation
from tests.service.conftest import submit, upload, wait_for_evaluation
from tests.verdict_factory import write_verdict_files

__all__ = ["browser", "page"]  # the fixtures, used by name

pytestmark = [pytest.mark.slow]


def test_a_closed_gate_says_why_on_the_page(
    page: Any, live_server_module: Any, tmp_path: Path
) -> None:
    """lost fails at 0.10@95 with fail_on fail: the card says CLOSED and the reason."""
    from playwright.sync_api import expect

    files = write_verdict_files(tmp_path / "runs")
    with live_server_module.client() as client:
        reference = {"dataset_id": upload(client, files["reference"])["id"]}
        lost = {"dataset_id": upload(client, files["lost"])["id"], "name": "lost"}
        options = {"tolerance": "0.10@95", "fail_on": ["fail"], "formats": ["summary.md"]}
        evaluation_id = submit(client, reference, [lost], options)["id"]
        done = wait_for_evaluation(client, evaluation_id)
    assert done["status"] == "succeeded"
    page.goto(f"{live_server_module.url}/")
    _enter_key(page, live_server_module.api_key)
    expect(_history_row(page, evaluation_id)).to_have_count(1)
    _open_evaluation(page, evaluation_id)
    gate = page.locator("#current-gate")
    expect(gate).to_be_visible()
    expect(gate.locator("#gate-status")).to_have_text("CLOSED")
    expect(gate.locator("#gate-conditions")).to_have_text("fails on fail")
    assert done["gate"]["passed"] is False
    reasons = done["gate"]["reasons"]
    assert reasons[0].startswith("lost fails the tolerance (")
    expect(gate.locator("#gate-reasons li")).to_have_text(reasons)  # the API's, word for word
    page.locator("#current-card").screenshot(path=str(tmp_path / "gate.png"))
    # the form offers the gate's conditions, made from the options table
    field = page.locator("#other-options-grid [data-option='fail_on']")
    expect(field).to_have_count(1)
