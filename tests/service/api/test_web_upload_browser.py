"""The page's resumable uploads (tus-js-client) in a real Chromium against a real server.

The vendored tus-js-client is checked against its pinned version and sums. Then the page
uploads a recording large enough to be caught midway (through a loopback proxy that is a
slow uplink, :mod:`tests.harness.proxy`): the network goes away (``context.set_offline``)
and comes back, and the upload completes with the file's bytes; a reload midway, then
choosing the same file, continues the upload from the server's offset instead of sending
the file again.
Screenshots at 1200 and 420 px are left in the test's tmp_path.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path
from typing import Any

import httpx2 as httpx
import numpy as np
import pytest

from service.api.web import TUS_JS_CLIENT_DIR
from tests.factories import write_large_tum
from tests.harness.processes import REPO
from tests.service.api.test_web_browser import _enter_key, browser, page
from tests.service.conftest import server_behind_proxy

pytestmark = [pytest.mark.slow]

__all__ = ["browser", "page"]  # the fixtures, imported for this module's tests

MIB = 1 << 20
UPLOAD_BYTES_PER_S = 3 * MIB  # a slow uplink: a 24 MB upload takes seconds
VENDOR = REPO / "templates" / TUS_JS_CLIENT_DIR


def test_vendored_tus_js_client_is_the_pinned_release() -> None:
    """The bundle and licence are byte for byte the sums; the bundle is VERSION's release."""
    for line in (VENDOR / "SHA256SUMS").read_text(encoding="utf-8").splitlines():
        digest, name = line.split()
        assert hashlib.sha256((VENDOR / name).read_bytes()).hexdigest() == digest, name
    version = (VENDOR / "VERSION").read_text(encoding="utf-8").strip()
    assert re.fullmatch(r"\d+\.\d+\.\d+", version)
    makefile = (REPO / "Makefile").read_text(encoding="utf-8")
    assert f"TUS_JS_CLIENT_VERSION ?= {version}" in makefile
    assert "MIT" in (VENDOR / "LICENSE").read_text(encoding="utf-8")


def test_the_page_serves_tus_js_client_offline(live_server: Any) -> None:
    """The page loads the bundle from the service itself, as a script, unchanged."""
    index = httpx.get(f"{live_server.url}/", timeout=10).text
    assert 'src="web/vendor/tus.min.js"' in index
    response = httpx.get(f"{live_server.url}/web/vendor/tus.min.js", timeout=10)
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/javascript")
    assert response.content == (VENDOR / "tus.min.js").read_bytes()


def _patches(page: Any) -> list[int]:
    """Collect the ``Upload-Offset`` of each PATCH the page sends from now on."""
    offsets: list[int] = []

    def seen(request: Any) -> None:
        if request.method == "PATCH" and "/api/v1/uploads/" in request.url:
            offsets.append(int(request.headers.get("upload-offset", "-1")))

    page.on("request", seen)
    return offsets


def _progress(page: Any) -> int:
    value = page.locator("#upload-list li [role=progressbar]").first.get_attribute("aria-valuenow")
    return int(value or 0)


def _dataset_of(live_server: Any, path: Path) -> dict[str, Any]:
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    response = httpx.get(
        f"{live_server.url}/api/v1/datasets",
        params={"sha256": digest},
        headers={"Authorization": f"Bearer {live_server.api_key}"},
        timeout=30,
    )
    response.raise_for_status()
    items: list[dict[str, Any]] = response.json()["items"]
    assert len(items) == 1, f"no dataset holds {path.name}'s bytes"
    return items[0]


def test_upload_survives_a_lost_network_and_a_reload(
    page: Any, tmp_path: Path, rng: np.random.Generator
) -> None:
    """Offline midway, then online: the upload completes. Reload midway: the same file resumes."""
    with server_behind_proxy(tmp_path / "data", bytes_per_s=UPLOAD_BYTES_PER_S) as (server, proxy):
        _lost_network_and_reload(page, server, proxy.url, tmp_path, rng)


def _lost_network_and_reload(
    page: Any, live_server: Any, url: str, tmp_path: Path, rng: np.random.Generator
) -> None:
    from playwright.sync_api import expect

    page.set_viewport_size({"width": 1200, "height": 900})
    page.goto(f"{url}/")
    _enter_key(page, live_server.api_key)
    expect(page.locator("#app")).to_be_visible()

    # 1. the network goes away midway and comes back
    first = write_large_tum(tmp_path / "walk-offline.txt", 20 * MIB, rng)
    page.set_input_files("#file-input", first)
    item = page.locator("#upload-list li").first
    expect(item).to_have_attribute("data-state", "uploading")
    expect(item.locator(".upload-message")).to_contain_text(re.compile(r"/s, .* left"))
    page.wait_for_function(
        "() => Number(document.querySelector('#upload-list li [role=progressbar]')"
        ".getAttribute('aria-valuenow')) >= 20"
    )
    page.screenshot(path=str(tmp_path / "uploading-1200.png"), full_page=False)
    page.context.set_offline(True)
    expect(item).to_have_attribute("data-state", "waiting-network", timeout=30_000)
    expect(item.locator(".upload-status")).to_contain_text("Waiting for the network")
    page.screenshot(path=str(tmp_path / "offline-1200.png"), full_page=False)
    page.context.set_offline(False)
    expect(item).to_have_attribute("data-state", re.compile("done|duplicate"), timeout=120_000)
    expect(item.locator("[role=progressbar]")).to_have_attribute("aria-valuenow", "100")
    dataset = _dataset_of(live_server, first)
    assert dataset["size_bytes"] == first.stat().st_size
    expect(item.locator(".upload-message")).to_contain_text("trajectory source")

    # 2. a reload midway; choosing the same file again continues it
    second = write_large_tum(tmp_path / "walk-reload.txt", 20 * MIB, rng)
    size = second.stat().st_size
    page.set_input_files("#file-input", second)
    page.wait_for_function(
        "() => { const li = document.querySelector('#upload-list li');"
        " return li && li.dataset.file === 'walk-reload.txt' && Number(li.querySelector("
        "'[role=progressbar]').getAttribute('aria-valuenow')) >= 50; }",
        timeout=60_000,
    )
    page.reload()
    expect(page.locator("#app")).to_be_visible()  # the key is remembered
    offsets = _patches(page)
    page.set_input_files("#file-input", second)
    item = page.locator("#upload-list li").first
    expect(item).to_have_attribute("data-state", re.compile("done|duplicate"), timeout=120_000)
    assert offsets, "the page sent no part after the reload"
    assert offsets[0] > 0, f"after the reload the upload started over: offsets {offsets}"
    assert offsets[0] >= size // 4  # it continued from what the server held (>= one part)
    assert _dataset_of(live_server, second)["size_bytes"] == size
    page.screenshot(path=str(tmp_path / "uploaded-1200.png"), full_page=False)
    page.set_viewport_size({"width": 420, "height": 900})
    page.locator("#upload-card").screenshot(path=str(tmp_path / "uploaded-420.png"))
