"""The browser page in a real Chromium against a real server: upload, evaluate, open the report.

The server is the ``live_server`` fixture of ``tests/service/conftest.py`` (a real
``loceval serve`` subprocess with its queue consumer); the browser is the system Chromium
driven by Playwright. Screenshots of the finished page (1280 px and 400 px wide) are left in
the test's tmp_path.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx2 as httpx
import pytest

from tests.conftest import skip_or_fail

pytestmark = [pytest.mark.slow]

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-quic",
    "--no-first-run",
    "--disable-component-update",
    "--disable-sync",
]
GROUNDTRUTH = "freiburg1_xyz-groundtruth.txt"
ESTIMATE = "freiburg1_xyz-rgbdslam.txt"
ESTIMATE_NAME = "rgbdslam run"
EVALUATION_TIMEOUT_MS = 120_000


# --- the browser -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """The system Chromium driven by Playwright (never a downloaded browser)."""
    if not CHROMIUM.is_file():
        skip_or_fail(f"{CHROMIUM} is not installed (apt package chromium)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        skip_or_fail("the playwright package is not installed (pip install playwright)")

    with sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            yield chromium
        finally:
            chromium.close()


@pytest.fixture
def page(browser: Any) -> Iterator[Any]:
    """A fresh browser context and page; uncaught script errors fail the test."""
    context = browser.new_context(viewport={"width": 1280, "height": 900}, accept_downloads=True)
    page = context.new_page()
    page.set_default_timeout(30_000)
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.on(
        "console",
        lambda msg: (
            errors.append(msg.text)
            if msg.type == "error" and "Failed to load resource" not in msg.text
            else None
        ),
    )
    yield page
    context.close()
    assert errors == [], f"script errors on the page: {errors}"


def _enter_key(page: Any, key: str) -> None:
    page.fill("#key-input", key)
    page.click("#key-form button[type=submit]")


def _choose(select: Any, label_part: str) -> None:
    """Select the option of ``select`` whose label contains ``label_part`` (waits for it)."""
    from playwright.sync_api import expect

    option = select.locator("option", has_text=label_part)
    expect(option).to_have_count(1)
    select.select_option(value=option.get_attribute("value"))


def refuse_option(
    page: Any, field: str, value: str, *, start: str, error: Any, option: str, says: list[str]
) -> None:
    """Enter ``value`` in ``field`` and press ``start``: the option is refused on the page.

    The ``error`` element says each of ``says`` and never ``options.`` (it names the page's
    field, not the API's ``options.KEY``), and the ``option`` field is marked invalid.
    """
    from playwright.sync_api import expect

    page.fill(field, value)
    page.click(start)
    for text in says:
        expect(error).to_contain_text(text)
    expect(error).not_to_contain_text("options.")
    expect(page.locator(f"[data-option='{option}']")).to_have_class(re.compile("invalid"))


def _api(server: Any, path: str) -> Any:
    response = httpx.get(
        f"{server.url}/api/v1{path}",
        headers={"Authorization": f"Bearer {server.api_key}"},
        timeout=30,
    )
    response.raise_for_status()
    return response.json()


def _upload_both(page: Any, public_data: Path) -> None:
    """Upload the two TUM files; each progress bar reaches 100 %; a re-upload says so."""
    from playwright.sync_api import expect

    page.set_input_files("#file-input", [public_data / GROUNDTRUTH, public_data / ESTIMATE])
    items = page.locator("#upload-list li")
    expect(items).to_have_count(2)
    finished = page.locator(
        "#upload-list li[data-state=done], #upload-list li[data-state=duplicate]"
    )
    expect(finished).to_have_count(2, timeout=60_000)
    for k in range(2):
        bar = items.nth(k).locator("[role=progressbar]")
        expect(bar).to_have_attribute("aria-valuenow", "100")

    # The same bytes again: the server answers 200 and the page says so.
    page.set_input_files("#file-input", public_data / GROUNDTRUTH)
    expect(items).to_have_count(3)
    expect(items.first).to_have_attribute("data-state", "duplicate", timeout=60_000)
    expect(items.first).to_contain_text("Already uploaded")

    # The dataset list shows both files with their one source.
    datasets = page.locator("#datasets-body tr")
    expect(datasets.filter(has_text=GROUNDTRUTH)).to_have_count(1)
    expect(datasets.filter(has_text=ESTIMATE)).to_contain_text("poses")


def wait_until_succeeded(page: Any) -> str | None:
    """Wait until the current evaluation's card shows it finished; it must have succeeded.

    Returns the card's evaluation id (the error the page shows is the assertion's message).
    """
    from playwright.sync_api import expect

    card = page.locator("#current-card")
    expect(card).to_be_visible()
    expect(card).to_have_attribute(
        "data-status", re.compile("succeeded|failed"), timeout=EVALUATION_TIMEOUT_MS
    )
    assert card.get_attribute("data-status") == "succeeded", page.inner_text("#current-error")
    evaluation_id: str | None = card.get_attribute("data-evaluation-id")
    return evaluation_id


def _evaluate(page: Any) -> str:
    """Fill the form, start, wait for the end; return the evaluation's id."""
    _choose(page.locator("#reference-select"), GROUNDTRUTH)
    _choose(page.locator(".estimate-select").first, ESTIMATE)
    page.locator(".estimate-name").first.fill(ESTIMATE_NAME)
    page.select_option("#opt-align", "se3")
    page.fill("#opt-tolerance", "0.10@95")
    page.click("#start-button")
    evaluation_id = wait_until_succeeded(page)
    assert evaluation_id
    return str(evaluation_id)


def _check_summary(page: Any, evaluation: Any) -> str:
    """The ATE RMSE on the page is the API's, printed like the report; return the text."""
    from playwright.sync_api import expect

    assert evaluation["status"] == "succeeded"
    (summary,) = evaluation["summary"]
    assert summary["name"] == ESTIMATE_NAME
    (estimate,) = evaluation["result"]["estimates"]
    assert estimate["ate"]["translation_m"]["rmse"] == summary["ate_rmse_m"]
    ate_cell = page.locator("#summary-body td.ate")
    assert float(ate_cell.get_attribute("data-value-m")) == summary["ate_rmse_m"]
    shown = str(ate_cell.inner_text())
    # the one rule for lengths: metres to the mm, or mm to a tenth when below 0.1 m
    value, unit = shown.split(" ")
    assert unit == ("mm" if summary["ate_rmse_m"] < 0.1 else "m")
    step = 0.0001 if unit == "mm" else 0.001
    metres = float(value) / (1000.0 if unit == "mm" else 1.0)
    assert abs(metres - summary["ate_rmse_m"]) <= step / 2 + 1e-12
    expect(page.locator("#summary-body")).to_contain_text(ESTIMATE_NAME)
    expect(page.locator("#summary-body")).to_contain_text(summary["verdict"].upper())
    return shown


def open_report(page: Any, evaluation: Any) -> str:
    """Check there is one button per artifact; open the report and return its HTML.

    The report opens in a new tab from a blob (the API needs the key, a link could not).
    """
    names = sorted(a["name"] for a in evaluation["artifacts"])
    buttons = page.locator("#artifact-list button[data-artifact]")
    assert sorted(buttons.evaluate_all("bs => bs.map(b => b.dataset.artifact)")) == names
    with page.expect_popup() as popup_info:
        page.click("#artifact-list button[data-artifact='report.html']")
    report = popup_info.value
    report.wait_for_url(re.compile(r"^blob:"), timeout=30_000)
    report.wait_for_load_state()
    html: str = report.content()
    report.close()
    return html


def _check_artifacts(page: Any, evaluation: Any, tmp_path: Path) -> None:
    """One button per artifact; the report opens in a tab, the others download."""
    html = open_report(page, evaluation)
    assert ESTIMATE_NAME in html
    assert "ATE" in html

    # Other artifacts download under names of their own: the evaluation's, then the file's.
    with page.expect_download() as download_info:
        page.click("#artifact-list button[data-artifact='result.json']")
    download = download_info.value
    assert download.suggested_filename == "rgbdslam_run-result.json"
    saved = tmp_path / "result.json"
    download.save_as(saved)
    assert saved.stat().st_size > 0


# --- tests -------------------------------------------------------------------------------


@pytest.mark.public_data
@pytest.mark.pdf  # the page asks for every artifact by default, report.pdf among them
def test_upload_evaluate_and_open_the_report(
    page: Any, live_server: Any, public_data: Path, tmp_path: Path
) -> None:
    from playwright.sync_api import expect

    page.goto(f"{live_server.url}/")
    expect(page.locator("#welcome")).to_be_visible()
    _enter_key(page, live_server.api_key)
    expect(page.locator("#app")).to_be_visible()
    expect(page.locator("#key-status")).to_contain_text(live_server.api_key[-4:])

    _upload_both(page, public_data)
    evaluation_id = _evaluate(page)
    evaluation = _api(live_server, f"/evaluations/{evaluation_id}")
    shown = _check_summary(page, evaluation)
    _check_artifacts(page, evaluation, tmp_path)

    # The past-evaluations table lists it, finished, with the same headline number.
    row = page.locator(f"#history-body tr[data-evaluation-id='{evaluation_id}']")
    expect(row).to_have_attribute("data-status", "succeeded")
    expect(row).to_contain_text(ESTIMATE_NAME)
    expect(row).to_contain_text(shown)

    page.screenshot(path=str(tmp_path / "web.png"), full_page=True)

    # A narrow window: nothing wider than the screen.
    page.set_viewport_size({"width": 400, "height": 900})
    overflow = page.evaluate("document.documentElement.scrollWidth - window.innerWidth")
    page.screenshot(path=str(tmp_path / "web-narrow.png"), full_page=True)
    assert overflow <= 0

    # Reload: the key is remembered, and reopening from the table shows the result.
    page.set_viewport_size({"width": 1280, "height": 900})
    page.reload()
    expect(page.locator("#app")).to_be_visible()
    row.get_by_role("button", name="Open").click()
    expect(page.locator("#current-card")).to_have_attribute("data-status", "succeeded")
    expect(page.locator("#summary-body td.ate")).to_have_text(shown)

    # Forgetting the key hides everything again.
    page.click("#key-forget")
    expect(page.locator("#welcome")).to_be_visible()
    assert page.evaluate("localStorage.getItem('loceval.apiKey')") is None


def test_wrong_key_asks_for_a_valid_one(page: Any, live_server: Any) -> None:
    from playwright.sync_api import expect

    page.goto(f"{live_server.url}/")
    _enter_key(page, "not-a-real-key")
    banner = page.locator("#banner")
    expect(banner).to_be_visible()
    expect(banner).to_contain_text("401")
    expect(banner).to_contain_text("valid key")
    expect(page.locator("#key-form")).to_be_visible()
    expect(page.locator("#app")).to_be_hidden()
    # A key the server never accepted is not remembered.
    assert page.evaluate("localStorage.getItem('loceval.apiKey')") is None

    # The right key after the wrong one works, and the message goes away.
    _enter_key(page, live_server.api_key)
    expect(page.locator("#app")).to_be_visible()
    expect(banner).to_be_hidden()


def test_page_and_assets_are_served_plainly(live_server: Any) -> None:
    """The page needs no key, names its media types, is revalidated, and loads nothing remote."""
    for path, media_type in [
        ("/", "text/html"),
        ("/web/app.js", "text/javascript"),
        ("/web/app.css", "text/css"),
    ]:
        response = httpx.get(f"{live_server.url}{path}", timeout=10)
        assert response.status_code == 200, path
        assert response.headers["content-type"].startswith(media_type), path
        assert response.headers["cache-control"] == "no-cache", path
        assert not re.search(r"(?:https?:)?//[a-z0-9.-]+\.[a-z]{2,}", response.text), path
    schema = httpx.get(f"{live_server.url}/openapi.json", timeout=10).json()
    assert not {"/", "/web/app.js", "/web/app.css"} & set(schema["paths"])


def test_unreadable_upload_shows_the_servers_reason(
    page: Any, live_server: Any, tmp_path: Path
) -> None:
    from playwright.sync_api import expect

    notes = tmp_path / "notes.txt"
    notes.write_text("meeting notes, not a trajectory\n<b>bold</b>\n", encoding="utf-8")
    page.goto(f"{live_server.url}/")
    _enter_key(page, live_server.api_key)
    page.set_input_files("#file-input", notes)
    item = page.locator("#upload-list li").first
    expect(item).to_have_attribute("data-state", "error", timeout=60_000)
    message = item.locator(".upload-message").inner_text()
    assert message
    assert "The server answered" not in message  # the problem's own words, not a fallback
    assert item.locator("b").count() == 0  # server text is never parsed as HTML


@pytest.mark.public_data
def test_tags_are_sent_and_a_dataset_can_be_deleted(
    page: Any, live_server: Any, public_data: Path
) -> None:
    from playwright.sync_api import expect

    page.goto(f"{live_server.url}/")
    _enter_key(page, live_server.api_key)
    page.fill("#tags-input", "floor2, web-test")
    page.set_input_files("#file-input", public_data / "motive_take_sample.csv")
    item = page.locator("#upload-list li").first
    expect(item).to_have_attribute("data-state", re.compile("done|duplicate"), timeout=60_000)

    row = page.locator("#datasets-body tr", has_text="motive_take_sample.csv")
    expect(row).to_have_count(1)
    if item.get_attribute("data-state") == "done":  # a duplicate keeps its first tags
        expect(row.locator(".tag")).to_have_text(["floor2", "web-test"])
    dataset_id = row.get_attribute("data-dataset-id")
    assert any(d["id"] == dataset_id for d in _api(live_server, "/datasets")["items"])

    page.once("dialog", lambda dialog: dialog.accept())
    row.get_by_role("button", name="Delete").click()
    expect(row).to_have_count(0)
    assert all(d["id"] != dataset_id for d in _api(live_server, "/datasets")["items"])
    expect(page.locator("#reference-select option", has_text="motive_take_sample")).to_have_count(0)
