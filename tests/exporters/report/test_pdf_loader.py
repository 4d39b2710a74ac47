"""WeasyPrint is imported once per process, and its absence is a clear export error.

WeasyPrint lays out only the PDFs of HTML templates of one's own (a folder without the
``.typ`` templates: the ``html_only_templates`` fixture); the repository's are typeset by
Typst and need no WeasyPrint.
"""

from __future__ import annotations

import threading
from pathlib import Path
from types import ModuleType

import pytest

from exporters.errors import ExportUnavailableError
from exporters.report import html_to_pdf, pdf_available
from exporters.report import render as report_render


@pytest.mark.usefixtures("no_weasyprint")
def test_missing_weasyprint_is_an_unavailable_export_every_time() -> None:
    """Without WeasyPrint every report says what to install, once looked for (not per call)."""
    for _ in range(2):
        with pytest.raises(ExportUnavailableError, match=r"libpango-1\.0-0") as caught:
            html_to_pdf(b"<p>x</p>")
        assert "\n" not in str(caught.value)
    assert isinstance(report_render._weasyprint_loaded, str)


@pytest.mark.usefixtures("no_weasyprint")
def test_pdf_available_is_false_without_weasyprint(html_only_templates: Path) -> None:
    """Without WeasyPrint the check says False (never raises) and keeps the outcome."""
    assert pdf_available(html_only_templates) is False
    assert pdf_available(html_only_templates) is False
    assert isinstance(report_render._weasyprint_loaded, str)  # the same cached outcome
    with pytest.raises(ExportUnavailableError, match=r"libpango-1\.0-0"):
        html_to_pdf(b"<p>x</p>")


@pytest.mark.usefixtures("no_weasyprint")
def test_the_repositorys_templates_need_no_weasyprint() -> None:
    """Typst typesets the default templates' PDFs: available without WeasyPrint."""
    assert pdf_available() is True
    assert report_render._weasyprint_loaded is None  # not even looked for


@pytest.mark.pdf
def test_pdf_available_is_true_with_weasyprint(
    monkeypatch: pytest.MonkeyPatch, html_only_templates: Path
) -> None:
    """With WeasyPrint and pango the check says True and keeps the loaded module."""
    monkeypatch.setattr(report_render, "_weasyprint_loaded", None)
    assert pdf_available(html_only_templates) is True
    assert isinstance(report_render._weasyprint_loaded, tuple)
    assert pdf_available(html_only_templates) is True


@pytest.mark.pdf
def test_threads_rendering_at_once_share_one_import(monkeypatch: pytest.MonkeyPatch) -> None:
    """Eight threads asking for WeasyPrint at once all get the same, whole module."""
    monkeypatch.setattr(report_render, "_weasyprint_loaded", None)
    start = threading.Barrier(8)
    modules: list[ModuleType] = []
    errors: list[BaseException] = []

    def load() -> None:
        start.wait()
        try:
            modules.append(report_render._weasyprint()[0])
        except BaseException as err:  # noqa: BLE001  (collected and asserted below)
            errors.append(err)

    threads = [threading.Thread(target=load) for _ in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors == []
    assert len(modules) == 8
    assert len({id(m) for m in modules}) == 1
    assert hasattr(modules[0], "HTML")
