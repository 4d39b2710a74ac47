"""What a newcomer still tripped on in the page (issue 44): advice, option labels, narrow screens.

Real Chromium (Playwright, the system package; the fixtures ``browser`` and ``page`` of
test_web_browser.py) against a real ``loceval serve`` shared by the module; the recordings
are generated, so no public data is needed. Screenshots at 1200 and 420 px are left in the
tests' tmp_path.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from loceval.options import OPTIONS
from loceval.readers.source import TrajectoryFormat
from tests.factories import make_trajectory, perturb, write_tum
from tests.service.api.test_web_browser import _enter_key, browser, page
from tests.service.conftest import upload

__all__ = ["browser", "page"]  # the fixtures, used by name

pytestmark = [pytest.mark.slow]

WIDTHS = (1200, 420)
LONGEST_LABEL = 28
"""The most characters of an option's label: a short name, its help is the tooltip."""


def _open(page: Any, server: Any) -> None:
    """Open the page with the project's key."""
    from playwright.sync_api import expect

    page.goto(f"{server.url}/")
    _enter_key(page, server.api_key)
    expect(page.locator("#app")).to_be_visible()


def test_an_unreadable_upload_gets_the_pages_own_advice(
    page: Any, live_server_module: Any, rng: np.random.Generator, tmp_path: Path
) -> None:
    """No format prefix the page cannot take: what is wrong, then the formats the server reads."""
    from playwright.sync_api import expect

    garbage = tmp_path / "garbage.bin"
    garbage.write_bytes(rng.bytes(3000))
    _open(page, live_server_module)
    page.set_input_files("#file-input", garbage)
    refused = page.locator("#upload-list li[data-state=error]")
    expect(refused).to_have_count(1)
    page.locator("#upload-card").screenshot(path=str(tmp_path / "unreadable.png"))
    text = refused.inner_text()
    assert "Cannot tell the format of 'garbage.bin'" in text
    for advice in ("prefix", "tum:", "e.g."):  # the command line's, not the page's
        assert advice not in text
    for fmt in TrajectoryFormat:  # the server's list of the readers' formats, every one
        assert fmt.shape in text
    assert "upload it again" in text


def test_other_options_are_short_names_with_bounds_a_person_types(
    page: Any, live_server_module: Any, tmp_path: Path
) -> None:
    """Labels come from the table's label (not its help); 1e+09 and 1e-09 are not shown."""
    _open(page, live_server_module)
    page.evaluate("document.getElementById('other-options').open = true")
    fields = page.locator("#other-options-grid [data-option]")
    shown = fields.evaluate_all(
        "fs => fs.map(f => [f.dataset.option, f.querySelector('span').firstChild.textContent,"
        " f.querySelector('span').textContent])"
    )
    page.locator("#other-options").screenshot(path=str(tmp_path / "other-options.png"))
    labels = {spec.key: spec.label for spec in OPTIONS}
    assert len(shown) >= 10
    assert {key for key, _, _ in shown} >= {"no_ci", "calibrate_at_s", "min_excursion_s"}
    for key, label, text in shown:
        assert label == labels[key], key
        assert 0 < len(label) <= LONGEST_LABEL, label
        assert not label.lower().startswith(("the ", "switch", "a ")), label
        assert "e+" not in text, text
        assert "e-" not in text, text
    by_key = {key: text for key, _, text in shown}
    assert by_key["no_ci"] == "No confidence intervals"
    assert by_key["calibrate_at_s"] == "Calibration time (s) (at least 0)"


def test_option_labels_are_short_names_in_the_table() -> None:
    """Every option the API takes has a label of its own, short and unlike its help."""
    for spec in OPTIONS:
        if not spec.api:
            continue
        assert 0 < len(spec.label) <= LONGEST_LABEL, spec.key
        assert spec.label[0].isupper(), spec.key
        assert spec.label.lower() != spec.help.lower()
        assert "e+" not in spec.bounds_hint
        assert "e-" not in spec.bounds_hint


def _long_evaluation(server: Any, rng: np.random.Generator, folder: Path) -> str:
    """Evaluate a 24,000-pose recording (the viewer draws fewer and says so); its id."""
    truth = make_trajectory(rng, 24_000)
    write_tum(folder / "long-truth.txt", truth)
    write_tum(folder / "long-run.txt", perturb(truth, rng))
    with server.client() as client:
        reference = upload(client, folder / "long-truth.txt")
        estimate = upload(client, folder / "long-run.txt")
        body = {
            "reference": {"dataset_id": reference["id"]},
            "estimates": [{"dataset_id": estimate["id"], "name": "long run"}],
            "options": {"formats": ["result.json", "viewer.html"], "tolerance": "0.10@95"},
        }
        answer = client.post("/api/v1/evaluations", json=body)
        assert answer.status_code == 202, answer.text
        evaluation_id: str = answer.json()["id"]
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:
            status = client.get(f"/api/v1/evaluations/{evaluation_id}").json()["status"]
            if status in {"succeeded", "failed"}:
                break
            time.sleep(0.5)
        assert status == "succeeded"
    return evaluation_id


_TEXT_FITS = """s => {
  const ctx = document.createElement("canvas").getContext("2d");
  ctx.font = getComputedStyle(s).font;
  return [ctx.measureText(s.options[s.selectedIndex].text).width, s.clientWidth];
}"""
_LINES = """b => { const r = document.createRange(); r.selectNodeContents(b);
  return new Set(Array.from(r.getClientRects(), (x) => Math.round(x.top))).size; }"""


def test_at_1200_and_420_px_nothing_is_cut(
    page: Any, live_server_module: Any, rng: np.random.Generator, tmp_path: Path
) -> None:
    """The Ranges choice reads whole; the viewer's Play is one line, its hint not clipped."""
    from playwright.sync_api import expect

    evaluation_id = _long_evaluation(live_server_module, rng, tmp_path)
    _open(page, live_server_module)
    row = page.locator(f"#history-body tr[data-evaluation-id='{evaluation_id}']")
    row.get_by_role("button", name="Open").click()
    frame = page.frame_locator("#current-viewer iframe")
    expect(frame.locator(".loceval-viewer[data-ready='true']")).to_have_count(1)
    expect(frame.locator(".lv-info")).to_contain_text("errors.csv has every pose")
    for width in WIDTHS:
        page.set_viewport_size({"width": width, "height": 900})
        page.wait_for_timeout(500)  # the frame lays itself out again
        page.screenshot(path=str(tmp_path / f"page-{width}.png"), full_page=True)
        page.locator("#current-viewer").screenshot(path=str(tmp_path / f"viewer-{width}.png"))
        for select in ("#ranging-ranges-select", "#ranging-anchors-select"):
            text_px, box_px = page.locator(select).evaluate(_TEXT_FITS)
            assert text_px + 24 <= box_px, (width, select, text_px, box_px)  # 24: the arrow
        play = frame.locator("[data-action=play]")
        assert play.evaluate(_LINES) == 1, width
        hint = frame.locator(".lv-info")
        height, content = hint.evaluate("e => [e.clientHeight, e.scrollHeight]")
        assert content <= height, (width, content, height)
