"""The browser page makes PDFs without pango; with HTML templates of its own it may not.

The page carries ``<body data-pdf-reports>``. With the repository's templates the server
always writes PDFs (Typst typesets them): no note, the ``report.pdf`` box ticked, even where
WeasyPrint cannot load. A server given HTML templates of its own needs WeasyPrint and pango
for their PDFs; without them its ``report.pdf`` box starts unticked and disabled with a note.
The browser test runs a real ``loceval serve`` whose ``import weasyprint`` fails as it does
where pango is missing (a stand-in package first on its PYTHONPATH): the page's defaults
make report.pdf and summary.pdf there. The fixtures ``browser`` and ``page`` are those of
test_web_browser.py.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import pytest

from exporters import ARTIFACTS
from exporters.report import render as report_render
from tests.service._api_fixtures import Api, open_api
from tests.service.api.test_web_browser import (
    EVALUATION_TIMEOUT_MS,
    _api,
    _enter_key,
    _evaluate,
    _upload_both,
    browser,
    page,
)
from tests.service.conftest import running_server

__all__ = ["browser", "page"]  # the fixtures, used by name

PDF_NOTE = "PDF reports of them need WeasyPrint and pango on the server"
_NO_PANGO = '''"""Stands in for WeasyPrint where its system library pango is missing."""
raise OSError(
    "cannot load library 'libpango-1.0-0': libpango-1.0-0: cannot open shared object file: "
    "No such file or directory"
)
'''


def _body(html: str) -> str:
    match = re.search(r"<body[^>]*>", html)
    assert match, html[:500]
    return match.group(0)


@pytest.mark.usefixtures("no_weasyprint")
def test_the_page_says_pdfs_can_be_written(api: Api, monkeypatch: pytest.MonkeyPatch) -> None:
    """The repository's templates, even without WeasyPrint: the flag says yes, no note."""
    monkeypatch.setattr(report_render, "_weasyprint_loaded", None)
    response = api.client.get("/")
    assert response.status_code == 200
    assert 'data-pdf-reports="yes"' in _body(response.text)
    assert PDF_NOTE not in response.text
    assert 'id="pdf-note"' not in response.text


@pytest.mark.usefixtures("no_weasyprint")
def test_the_page_says_pdfs_cannot_be_written(tmp_path: Path, html_only_templates: Path) -> None:
    """HTML templates of its own, no WeasyPrint: the flag says no, the note what to install."""
    with open_api(tmp_path, templates_dir=html_only_templates) as api:
        response = api.client.get("/")
    assert response.status_code == 200
    assert 'data-pdf-reports="no"' in _body(response.text)
    assert 'id="pdf-note"' in response.text
    assert PDF_NOTE in response.text
    assert "libpango-1.0-0" in response.text
    assert "loceval[html-pdf]" in response.text


def _without_pango(folder: Path) -> dict[str, str]:
    """The environment of a server whose ``import weasyprint`` fails like a missing pango."""
    package = folder / "weasyprint"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text(_NO_PANGO, encoding="utf-8")
    paths = [str(folder), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    return {"PYTHONPATH": os.pathsep.join(paths)}


@pytest.mark.slow
@pytest.mark.public_data
def test_the_pages_defaults_work_without_pango(
    page: Any, public_data: Path, tmp_path: Path
) -> None:
    """No pango: the page's defaults make report.pdf, and its schedules summary.pdf."""
    from playwright.sync_api import expect

    env = _without_pango(tmp_path / "no-pango")
    with running_server(tmp_path / "data", env=env) as server:
        page.goto(f"{server.url}/")
        _enter_key(page, server.api_key)
        expect(page.locator("#app")).to_be_visible()
        expect(page.locator("#pdf-note")).to_have_count(0)
        pdf_box = page.locator("#format-boxes input[value='report.pdf']")
        expect(pdf_box).to_be_checked()
        expect(pdf_box).to_be_enabled()
        expect(page.locator("#format-boxes input:checked")).to_have_count(len(ARTIFACTS))

        # Upload and evaluate with the page's files: it succeeds and writes the PDF.
        page.fill("#tags-input", "floor2")
        _upload_both(page, public_data)
        evaluation = _api(server, f"/evaluations/{_evaluate(page)}")
        assert evaluation["status"] == "succeeded"
        assert evaluation["options"]["formats"] is None  # every file: the API's default
        names = sorted(a["name"] for a in evaluation["artifacts"])
        assert names == sorted(ARTIFACTS)
        buttons = page.locator("#artifact-list button[data-artifact]")
        assert sorted(buttons.evaluate_all("bs => bs.map(b => b.dataset.artifact)")) == names
        page.screenshot(path=str(tmp_path / "no-pango.png"), full_page=True)

        # A schedule made on the page writes both summaries, and its run succeeds.
        page.click("#schedule-create > summary")
        expect(page.locator("#pdf-note-schedules")).to_have_count(0)
        page.fill("#sched-name", "Weekly floor 2")
        page.fill("#sched-cron", "0 7 * * mon")
        page.fill("#sched-tags", "floor2")
        page.click("#schedule-create-button")
        row = page.locator("#schedules-body tr", has_text="Weekly floor 2")
        expect(row).to_have_count(1)
        (schedule,) = _api(server, "/schedules")["items"]
        assert schedule["produce"]["summary_formats"] == ["summary.html", "summary.pdf"]
        row.get_by_role("button", name="Run now").click()
        expect(row.get_by_role("button", name="Open summary")).to_be_visible(
            timeout=EVALUATION_TIMEOUT_MS
        )
        expect(row.locator(".last-run")).to_contain_text("Succeeded")
        (run,) = _api(server, f"/schedules/{schedule['id']}/runs")["items"]
        assert [a["name"] for a in run["artifacts"]] == ["summary.html", "summary.pdf"]
