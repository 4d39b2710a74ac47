"""Issue 44's report items: a quiet log, a complete contents list, file names kept whole.

- 4: a report adds no ``weasyprint.progress`` lines and no ``print-color-adjust`` warnings
  to the log (Typst typesets the PDF; WeasyPrint, for HTML templates of one's own, is
  kept quiet);
- 8: the contents list names every section the report has (the interactive view and the
  clocks included), in the HTML and in the PDF;
- 9: a file name in the PDF's tables breaks after a path separator or not at all (never
  ``fr2_desk_ / groundtruth`` or ``tum:fr2_desk_ORB. / txt``).
"""

from __future__ import annotations

import logging
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from exporters.options import ExportOptions
from exporters.report import render_report, render_report_pdf
from loceval.evaluation import EvaluationResult, evaluate
from loceval.trajectory import Trajectory
from tests.exporters._pdf_text import normalise, pdf_pages
from tests.exporters.conftest import noisy, walk

# --- item 4: the log --------------------------------------------------------------------


def _small(rng: np.random.Generator) -> EvaluationResult:
    truth = walk(rng, n=1500)
    return evaluate(truth, [noisy(rng, truth, every=2, sigma=0.02, drift=0.0, name="VIO")])


def _noise(records: list[logging.LogRecord]) -> list[str]:
    return [
        f"{r.name}: {r.getMessage()}"
        for r in records
        if r.name.startswith("weasyprint") or "print-color-adjust" in r.getMessage()
    ]


def test_a_report_logs_no_weasyprint_lines(
    rng: np.random.Generator, caplog: pytest.LogCaptureFixture
) -> None:
    """report.pdf and report.html add nothing of WeasyPrint's to the log, at any level."""
    result = _small(rng)
    with caplog.at_level(logging.DEBUG):
        _, pdf = render_report(result)
    assert pdf.startswith(b"%PDF")
    assert _noise(caplog.records) == []
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]


@pytest.mark.pdf
def test_html_templates_laid_out_by_weasyprint_log_no_progress(
    rng: np.random.Generator, caplog: pytest.LogCaptureFixture, html_only_templates: Path
) -> None:
    """A folder of HTML templates has WeasyPrint lay out its PDF, quietly: no per-step lines."""
    result = _small(rng)
    with caplog.at_level(logging.INFO):
        pdf = render_report_pdf(result, ExportOptions(templates_dir=html_only_templates))
    assert pdf.startswith(b"%PDF")
    assert _noise(caplog.records) == []


# --- item 8: the contents list -----------------------------------------------------------


class _Sections(HTMLParser):
    """Collects the contents list's links and each section's id and first heading."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.contents: list[tuple[str, str]] = []
        self.sections: list[tuple[str, str]] = []
        self._link: str | None = None
        self._section: str | None = None
        self._heading = False
        self._text: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        found = dict(attrs)
        if tag == "a" and (href := found.get("href") or "").startswith("#"):
            self._link, self._text = href[1:], []
        elif tag == "section" and found.get("id"):
            self._section = found["id"]
        elif tag == "h2" and self._section is not None:
            self._heading, self._text = True, []

    def handle_endtag(self, tag: str) -> None:
        if tag == "a" and self._link is not None:
            self.contents.append((self._link, normalise("".join(self._text))))
            self._link = None
        elif tag == "h2" and self._heading:
            assert self._section is not None
            self.sections.append((self._section, normalise("".join(self._text))))
            self._heading, self._section = False, None

    def handle_data(self, data: str) -> None:
        if self._link is not None or self._heading:
            self._text.append(data)


def _ranging() -> EvaluationResult:
    from loceval.radio_evaluation import RangingConfig, evaluate_radio
    from tests.radio_factory import make_ranges, make_reference

    rng = np.random.default_rng(10)
    return evaluate_radio(make_reference(), make_ranges(rng, end_s=20.0).ranges, RangingConfig())


@pytest.mark.parametrize("kind", ["trajectory", "ranging"])
def test_the_contents_name_every_section(kind: str, tmp_path: Path) -> None:
    """Each section of the report (with its heading) has its entry, in order, in both files."""
    result = _small(np.random.default_rng(3)) if kind == "trajectory" else _ranging()
    title = "Contents check"
    html, pdf = render_report(result, options=ExportOptions(title=title))
    parsed = _Sections()
    parsed.feed(html.decode("utf-8"))
    sections = parsed.sections
    assert ("viewer", "interactive view") in sections
    assert ("clocks", "clocks and device offset") in sections
    assert [anchor for anchor, _ in parsed.contents] == [anchor for anchor, _ in sections]
    for (_, entry), (anchor, heading) in zip(parsed.contents, sections, strict=True):
        assert entry.startswith(heading), (anchor, entry, heading)
    # The PDF's contents: every section it has (all but the interactive view), with a page.
    entry = re.compile(r"^(.*?)(?: ?\.){3,} ?(\d+)$")
    listed = [m.groups() for line in pdf_pages(pdf, tmp_path)[0] if (m := entry.match(line))]
    in_pdf = [heading for anchor, heading in sections if anchor != "viewer"]
    assert [normalise(t) for t, _ in listed] == [
        entry for anchor, entry in parsed.contents if anchor != "viewer"
    ]
    assert len(in_pdf) == len(listed)
    pages = [int(page) for _, page in listed]
    assert pages == sorted(pages)


# --- item 9: file names in the PDF's tables ----------------------------------------------

NAMES = (
    "rgbd_dataset_freiburg2_desk_groundtruth.txt",
    "tum:fr2_desk_ORB_SLAM3_monocular_estimate.txt",
    "orbslam3_monocular_run_2026-11-29",
)


def _named(rng: np.random.Generator) -> EvaluationResult:
    """Names as sites give them: long, with _ . - and : inside, a path with folders."""
    truth = walk(rng, n=1500)
    truth = Trajectory(
        truth.stamps_ns,
        truth.positions_xyz,
        truth.quat_xyzw,
        name="fr2_desk_groundtruth",
        source=f"tum:/srv/recordings/site-7/level-2/{NAMES[0]}",
    )
    est = noisy(rng, truth, every=2, sigma=0.02, drift=0.0, name=NAMES[2])
    est = Trajectory(
        est.stamps_ns, est.positions_xyz, est.quat_xyzw, name=NAMES[2], source=NAMES[1]
    )
    inputs = (
        {
            "role": "reference",
            "path": f"/srv/recordings/site-7/level-2/{NAMES[0]}",
            "file": NAMES[0],
            "format": "tum",
            "selector": None,
            "sha256": "c" * 64,
            "bytes": 1_400_000,
        },
        {
            "role": "estimate",
            "path": "/srv/recordings/site-7/level-2/fr2_desk_ORB_SLAM3_monocular_estimate.txt",
            "file": NAMES[1].removeprefix("tum:"),
            "format": "tum",
            "selector": "tf:map:base_link_of_the_robot",
            "sha256": "d" * 64,
            "bytes": 303_400,
        },
    )
    return evaluate(truth, [est], inputs=inputs)


def test_file_names_break_at_path_separators_or_not_at_all(
    rng: np.random.Generator, tmp_path: Path
) -> None:
    """In the PDF's text every name is whole on its line, or split right after a ``/``."""
    _, pdf = render_report(_named(rng))
    text = "\n".join("\n".join(page) for page in pdf_pages(pdf, tmp_path))
    for name in (*NAMES, NAMES[1].removeprefix("tum:"), "tf:map:base_link_of_the_robot"):
        assert name in text.replace("/\n", "/"), name
        # whole on one line wherever it appears, but after a folder's "/"
        pattern = re.escape(name).replace("/", "/\\n?")
        found = re.findall(pattern, text)
        assert found, name
        for piece in re.findall(r"\S*\n\S*", text):
            head, tail = piece.split("\n")
            joined = head + tail
            if name in joined and name not in head and name not in tail:
                assert head.endswith("/"), (name, piece)
