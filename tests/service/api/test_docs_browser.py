"""The API documentation page, ``/docs``, in a real Chromium: it renders and "Try it out" works.

Swagger UI is vendored (``templates/web/vendor/swagger-ui``); the first test checks its files
against the sums the refresh command wrote, the others open ``/docs`` on a real
``loceval serve`` (the shared ``live_server_module``) in the system Chromium driven by
Playwright (the fixtures ``browser`` and ``page`` of test_web_browser.py). Every request the
page makes must go to the service itself. Screenshots are left in the test's tmp_path.
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path
from typing import Any

import httpx2 as httpx
import pytest

from service.api.docs import SWAGGER_UI_DIR
from tests.service.api.test_web_browser import browser, page

__all__ = ["browser", "page"]  # the fixtures, used by name

ROOT = Path(__file__).resolve().parents[3]
VENDORED = ROOT / "templates" / SWAGGER_UI_DIR
PAGE_FILES = ["swagger-ui-bundle.js", "swagger-ui.css", "favicon-32x32.png"]


def test_vendored_swagger_ui_is_the_pinned_release_unmodified() -> None:
    """Each vendored file has the SHA-256 the refresh wrote; the bundle is VERSION, a 5.x."""
    sums = {}
    for line in (VENDORED / "SHA256SUMS").read_text(encoding="utf-8").splitlines():
        digest, name = line.split()
        sums[name] = digest
    assert set(PAGE_FILES) | {"LICENSE", "NOTICE"} <= set(sums)
    for name, digest in sums.items():
        assert hashlib.sha256((VENDORED / name).read_bytes()).hexdigest() == digest, name
    # nothing else in the folder: no map files, no unlisted edits
    assert {p.name for p in VENDORED.iterdir()} == set(sums) | {
        "VERSION",
        "SHA256SUMS",
        "README.md",
    }
    version = (VENDORED / "VERSION").read_text(encoding="utf-8").strip()
    assert re.fullmatch(r"5\.\d+\.\d+", version), version  # 5.x renders OpenAPI 3.1
    bundle = (VENDORED / "swagger-ui-bundle.js").read_text(encoding="utf-8")
    assert f'PACKAGE_VERSION:"{version}"' in bundle
    assert "Apache License" in (VENDORED / "LICENSE").read_text(encoding="utf-8")
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    assert f"SWAGGER_UI_VERSION ?= {version}\n" in makefile  # the refresh command's pin


def _operations(server: Any) -> list[tuple[str, str]]:
    document = httpx.get(f"{server.url}/openapi.json", timeout=10).json()
    assert document["openapi"].startswith("3.1")
    # the page's introduction names every CAD format the API writes (IFC was left out)
    for name in ("DXF", "3dm", "glTF", "IFC"):
        assert name in document["info"]["description"], name
    return [(method.upper(), path) for path, ops in document["paths"].items() for method in ops]


def _authorize(page: Any, key: str) -> None:
    """Authorize with the API key in Swagger UI's dialog."""
    page.click("button.authorize")
    dialog = page.locator(".modal-ux")
    dialog.get_by_label("Value").fill(key)
    dialog.get_by_role("button", name="Apply credentials").click()
    dialog.get_by_role("button", name="Close").click()


@pytest.mark.slow
def test_docs_lists_every_operation_and_try_it_out_sends_the_key(
    page: Any, live_server_module: Any, tmp_path: Path
) -> None:
    """/docs renders the 3.1 document offline; Try it out with the key answers 200."""
    from playwright.sync_api import expect

    requests: list[str] = []
    page.on("request", lambda request: requests.append(request.url))
    page.goto(f"{live_server_module.url}/docs")

    operations = _operations(live_server_module)
    blocks = page.locator(".opblock")
    expect(blocks).to_have_count(len(operations), timeout=30_000)
    expect(page.locator("body")).not_to_contain_text("Unable to render this definition")
    shown = blocks.evaluate_all(
        "bs => bs.map(b => [b.querySelector('.opblock-summary-method').textContent,"
        " b.querySelector('.opblock-summary-path').dataset.path])"
    )
    assert sorted(map(tuple, shown)) == sorted(operations)
    page.screenshot(path=str(tmp_path / "docs.png"), full_page=True)

    _authorize(page, live_server_module.api_key)
    block = page.locator(".opblock-get", has=page.locator("[data-path='/api/v1/datasets']"))
    block.locator(".opblock-summary").click()
    block.get_by_role("button", name="Try it out").click()
    with page.expect_request(re.compile(r"/api/v1/datasets(\?.*)?$")) as sent:
        block.get_by_role("button", name="Execute").click()
    assert sent.value.headers["authorization"] == f"Bearer {live_server_module.api_key}"
    live = block.locator(".live-responses-table .response .response-col_status")
    expect(live).to_have_text("200", timeout=30_000)
    expect(block.locator(".live-responses-table")).to_contain_text('"items"')
    page.screenshot(path=str(tmp_path / "docs-try-it-out.png"), full_page=True)

    # Nothing was asked of another host: the page, its files and the API are the service's.
    foreign = [u for u in requests if not u.startswith((live_server_module.url, "data:", "blob:"))]
    assert foreign == []


@pytest.mark.slow
def test_docs_without_the_key_shows_the_servers_401(page: Any, live_server_module: Any) -> None:
    """Try it out before Authorize: the 401 problem is shown, not a blank response."""
    from playwright.sync_api import expect

    page.goto(f"{live_server_module.url}/docs")
    block = page.locator(".opblock-get", has=page.locator("[data-path='/api/v1/datasets']"))
    block.locator(".opblock-summary").click()
    block.get_by_role("button", name="Try it out").click()
    block.get_by_role("button", name="Execute").click()
    live = block.locator(".live-responses-table .response .response-col_status")
    expect(live).to_contain_text("401", timeout=30_000)


@pytest.mark.slow
def test_docs_shows_real_answers_under_each_status(
    page: Any, live_server_module: Any, tmp_path: Path
) -> None:
    """Each status's example on the page is of that status; none is "string" or random junk."""
    from tests.service.api.test_docs_examples import _strings, looks_random

    page.goto(f"{live_server_module.url}/docs")
    page.wait_for_selector(".opblock")
    controls = page.locator(".opblock-summary-control")
    for k in range(controls.count()):
        controls.nth(k).click()
    shown = page.locator("tr.response pre.example code")
    shown.first.wait_for()
    page.wait_for_timeout(1000)  # the last blocks' examples
    page.screenshot(path=str(tmp_path / "docs-examples.png"), full_page=True)
    rows = page.evaluate(
        """() => Array.from(document.querySelectorAll('.opblock')).flatMap(op => {
          const path = op.querySelector('.opblock-summary-path').dataset.path;
          return Array.from(op.querySelectorAll('tr.response')).map(r => [path,
            r.dataset.code, (r.querySelector('pre.example code') || {}).textContent || null]);
        })"""
    )
    examples = [(path, code, text) for path, code, text in rows if text]
    assert len(examples) >= 100
    for path, code, text in examples:
        where = f"{path} {code}"
        assert '"additionalProp1"' not in text, where
        assert '"string"' not in text, where
        if not text.lstrip().startswith(("{", "[")):  # the metrics' text
            assert not looks_random(text), where
            continue
        document = json.loads(text)
        for words in _strings(document):
            assert not looks_random(words), (where, words)
        if isinstance(document, dict) and code.startswith(("4", "5")) and "status" in document:
            assert document["status"] == int(code), where
