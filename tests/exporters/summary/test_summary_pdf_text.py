"""summary.pdf and the control-point report.pdf (Typst) print what their HTML prints.

As for the evaluation report (``test_report_pdf_text.py``): each case renders one view
model as HTML (Jinja2) and as PDF (Typst) and compares the text block by block, both ways.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from exporters.options import ExportOptions
from exporters.report import DEFAULT_TEMPLATES_DIR, render_template
from exporters.report.checkpoints import (
    CHECKPOINT_PDF_TEMPLATE,
    CHECKPOINT_TEMPLATE,
    build_checkpoint_view,
)
from exporters.report.typeset import typeset_pdf
from exporters.summary import (
    SummaryInput,
    SummaryRun,
    SystemFigures,
    build_summary_view,
    render_summary_view_html,
    render_summary_view_pdf,
)
from exporters.summary.evo import evo_summary_run
from exporters.summary.model import BaselineLine
from loceval.readers.evo_result import read_result_zip
from tests.checkpoint_factory import survey_evaluation
from tests.exporters._pdf_text import text_differences
from tests.exporters.summary.test_summary import _failed, _loop, _run, _summary, _week_runs
from tests.exporters.summary.test_summary_evo import EVO, MONDAY


def _against_baseline() -> SummaryInput:
    """Runs of a schedule with a pinned baseline: each run's systems against it."""
    runs = _week_runs(np.random.default_rng(6), count=3)
    lines = (
        BaselineLine("RTAB-Map", "ATE RMSE", 0.012, (0.004, 0.02), "worse"),
        BaselineLine("ISAAC", "ATE RMSE", -0.001, (-0.006, 0.004), "within_noise"),
        BaselineLine("ISAAC", "RPE RMSE", -0.004, None, "undetermined"),
    )
    runs = [
        r if r.status == "failed" else replace(r, baseline=lines, baseline_label="evaluation ev-7")
        for r in runs
    ]
    return _summary(runs)


SUMMARIES: dict[str, Callable[[], SummaryInput]] = {
    "runs against a pinned baseline": _against_baseline,
    "a week, two systems, one failed": lambda: _summary(_week_runs(np.random.default_rng(5))),
    "nothing matched": lambda: _summary([]),
    "every run failed": lambda: _summary([_failed(0), _failed(1, "No estimate topic.")]),
    "one run, no tolerance": lambda: _summary(
        [_run(0, {"A": SystemFigures(0.04, 0.01, 100, None)}, xyz=_loop(500))], tolerance=None
    ),
    "an evo result beside a run": lambda: SummaryInput(
        title="Weekly",
        generated_at=MONDAY,
        selection="recordings",
        runs=[
            SummaryRun(
                dataset="level2-run0.bag",
                recorded_at=MONDAY,
                status="succeeded",
                systems={"/odom": SystemFigures(0.30, 0.02, 100, None)},
            ),
            evo_summary_run(
                read_result_zip(EVO / "nav2_amcl_odom_ape_se3.zip"),
                dataset="archive.zip",
                recorded_at=MONDAY - dt.timedelta(days=7),
            ),
        ],
    ),
}


@pytest.mark.parametrize("case", list(SUMMARIES))
def test_summary_pdf_prints_what_the_html_prints(case: str, tmp_path: Path) -> None:
    """Every block of the summary's HTML is in its PDF, and the PDF holds nothing else."""
    summary = SUMMARIES[case]()
    view = build_summary_view(summary, image_format="svg")
    html = render_summary_view_html(view, templates_dir=DEFAULT_TEMPLATES_DIR).decode()
    pdf = render_summary_view_pdf(view, templates_dir=DEFAULT_TEMPLATES_DIR)
    missing, extra = text_differences(html, pdf, tmp_path, title=summary.title)
    assert missing == [], missing
    assert extra == [], extra


def test_checkpoint_pdf_prints_what_the_html_prints(
    rng: np.random.Generator, tmp_path: Path
) -> None:
    """The control-point report: survey, one section per estimate, warnings; both ways."""
    evaluation = survey_evaluation(rng)
    options = ExportOptions(title="Level 2 control points", evaluation_id="cp-1")
    view = build_checkpoint_view(evaluation, options, image_format="svg")
    html = render_template(
        DEFAULT_TEMPLATES_DIR,
        CHECKPOINT_TEMPLATE,
        label="control-point report",
        requirement="report.html",
        report=view,
        viewer=None,
    ).decode()
    pdf = typeset_pdf(DEFAULT_TEMPLATES_DIR / CHECKPOINT_PDF_TEMPLATE, view, label="checkpoints")
    missing, extra = text_differences(html, pdf, tmp_path, title=options.title)
    assert missing == [], missing
    assert extra == [], extra
