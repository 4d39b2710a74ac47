"""The page's evaluation card shows the interactive viewer once the evaluation succeeded.

A real ``loceval serve`` and the system Chromium (WebGL by SwiftShader): upload, evaluate,
and the card's viewer (the evaluation's ``viewer.html`` in a sandboxed frame) gets ready,
follows its timeline with the ATE of ``errors.csv`` and never asks another host for anything.
"""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import httpx2 as httpx
import pytest

from tests.conftest import skip_or_fail
from tests.service.api.test_web_browser import (
    CHROMIUM,
    ESTIMATE_NAME,
    _enter_key,
    _evaluate,
    _upload_both,
)

pytestmark = [pytest.mark.slow]

ARGS = [
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-quic",
    "--no-first-run",
    "--disable-component-update",
    "--disable-sync",
]


@pytest.fixture
def page() -> Iterator[Any]:
    """A page of the system Chromium with WebGL; records problems and every request."""
    if not CHROMIUM.is_file():
        skip_or_fail(f"{CHROMIUM} is not installed (apt package chromium)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        skip_or_fail("the playwright package is not installed (pip install playwright)")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
        page = browser.new_page(viewport={"width": 1280, "height": 1000})
        page.set_default_timeout(30_000)
        page.problems = []  # type: ignore[attr-defined]
        page.requests = []  # type: ignore[attr-defined]
        page.on("pageerror", lambda exc: page.problems.append(str(exc)))
        page.on("console", lambda m: page.problems.append(m.text) if m.type == "error" else None)
        page.on("request", lambda r: page.requests.append(r.url))
        try:
            yield page
        finally:
            browser.close()


@pytest.mark.public_data
def test_card_shows_the_viewer(
    page: Any, live_server: Any, public_data: Path, tmp_path: Path
) -> None:
    """Evaluate on the page: the card's viewer is ready, its timeline gives errors.csv's ATE."""
    from playwright.sync_api import expect

    page.goto(f"{live_server.url}/")
    _enter_key(page, live_server.api_key)
    _upload_both(page, public_data)
    evaluation_id = _evaluate(page)

    page.locator("#current-viewer iframe").scroll_into_view_if_needed()
    frame = page.frame_locator("#current-viewer iframe")
    root = frame.locator(".loceval-viewer")
    expect(root).to_have_attribute("data-ready", "true", timeout=60_000)
    expect(frame.locator(".lv-paths label")).to_have_count(2)
    expect(frame.locator(".lv-paths")).to_contain_text(ESTIMATE_NAME)

    response = httpx.get(
        f"{live_server.url}/api/v1/evaluations/{evaluation_id}/artifacts/errors.csv",
        headers={"Authorization": f"Bearer {live_server.api_key}"},
        timeout=30,
    )
    response.raise_for_status()
    rows = [r for r in csv.DictReader(io.StringIO(response.text)) if r["estimate"] == ESTIMATE_NAME]
    slider = frame.locator("input[type=range]")
    top = int(slider.get_attribute("max"))
    for i in (top // 4, top // 2, (3 * top) // 4):
        slider.fill(str(i))
        t = float(root.get_attribute("data-time-s"))
        errors = json.loads(root.get_attribute("data-errors"))
        nearest = min(rows, key=lambda r: abs(float(r["t_s"]) - t))
        assert errors[ESTIMATE_NAME] == float(nearest["ate_m"])

    folder = Path(os.environ.get("LOCEVAL_SCREENSHOTS", tmp_path))
    folder.mkdir(parents=True, exist_ok=True)
    page.locator("#current-card").screenshot(path=str(folder / "page_card_viewer.png"))
    origin = urlsplit(live_server.url).netloc
    foreign = [
        u
        for u in page.requests
        if urlsplit(u).scheme in ("http", "https", "ws", "wss") and urlsplit(u).netloc != origin
    ]
    assert foreign == []
    assert page.problems == []
