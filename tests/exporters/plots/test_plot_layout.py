"""The figures' fixed layouts fit every decoration, as constrained layout did.

Each figure the report, the summary and the control-point report draw is laid out by
measuring its texts: the figure kit's (:mod:`exporters.plots.svg`) by DejaVu's advance
widths, matplotlib's (:mod:`exporters.plots.layout`) instead of its constrained layout.
Checked here: matplotlib's figures with matplotlib's own full measure (``get_tightbbox``,
what constrained layout walks), the kit's with the box of every text it drew. No tick
label, axis label, title, note or legend runs off the figure, none lies on another axes'
plotting area, a figure's legend sits above every axes, and a colour bar stands clear of
its plot.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.transforms import Bbox

from exporters.options import ExportOptions
from exporters.plots import mpl as mpl_module
from exporters.plots.svg.canvas import Figure as KitFigure
from exporters.plots.svg.draw import Box
from exporters.report import render_report_plots
from loceval.evaluation import EvaluationResult

TOLERANCE_PX = 1.5


def _figures(
    monkeypatch: pytest.MonkeyPatch, draw: Callable[[], object]
) -> Iterator[tuple[str, Figure | KitFigure]]:
    """Run ``draw`` and yield each figure it laid out, by its position in the run."""
    laid: list[Figure | KitFigure] = []
    lay_out = mpl_module._lay_out_once
    svg = KitFigure.svg

    def keep(fig: Figure) -> None:
        lay_out(fig)
        laid.append(fig)

    def keep_kit(fig: KitFigure) -> bytes:
        laid.append(fig)
        return svg(fig)

    monkeypatch.setattr(mpl_module, "_lay_out_once", keep)
    monkeypatch.setattr(KitFigure, "svg", keep_kit)
    draw()
    monkeypatch.undo()
    yield from ((f"figure {n}", fig) for n, fig in enumerate(laid, start=1))


def _inside(box: Box, page: Box) -> bool:
    slack = TOLERANCE_PX
    return (
        box.left >= page.left - slack
        and box.top >= page.top - slack
        and box.right <= page.right + slack
        and box.bottom <= page.bottom + slack
    )


def _meet(a: Box, b: Box) -> bool:
    return (
        min(a.right, b.right) - max(a.left, b.left) > TOLERANCE_PX
        and min(a.bottom, b.bottom) - max(a.top, b.top) > TOLERANCE_PX
    )


def _check_kit(name: str, fig: KitFigure) -> list[str]:
    """What of a kit figure is cut off or lies where it should not (empty when it fits).

    Every text the figure drew (``Figure.text_boxes``): on the page; an axes' texts off
    every other axes' plotting area; the legend above and the colour bar's texts beside
    every plotting area. Points, against a slack of 1.5 points.
    """
    page = Box(0.0, 0.0, fig.width_pt, fig.height_pt)
    areas = {f"axes {k}": ax.box for k, ax in enumerate(fig.axes)}
    problems = []
    for owner, boxes in fig.text_boxes.items():
        for box in boxes:
            if not _inside(box, page):
                problems.append(f"{name}: a text of {owner} runs off the figure: {box}")
            problems += [
                f"{name}: a text of {owner} lies on {other}: {box}"
                for other, area in areas.items()
                if other != owner and _meet(box, area)
            ]
    return problems


def _overlap(a: Bbox, b: Bbox) -> bool:
    return (
        min(a.x1, b.x1) - max(a.x0, b.x0) > TOLERANCE_PX
        and min(a.y1, b.y1) - max(a.y0, b.y0) > TOLERANCE_PX
    )


def _check(name: str, fig: Figure) -> list[str]:
    """What of the figure is cut off or lies on another axes (empty when it fits)."""
    renderer = fig._get_renderer()
    fig.draw_without_rendering()  # the labels where a draw puts them
    page = fig.bbox
    problems = []
    axes = [ax for ax in fig.axes if ax.get_visible()]
    for k, ax in enumerate(axes):
        tight = ax.get_tightbbox(renderer)
        assert tight is not None
        if (
            tight.x0 < page.x0 - TOLERANCE_PX
            or tight.y0 < page.y0 - TOLERANCE_PX
            or tight.x1 > page.x1 + TOLERANCE_PX
            or tight.y1 > page.y1 + TOLERANCE_PX
        ):
            problems.append(f"{name}: axes {k} reaches off the figure: {tight} beyond {page}")
        for j, other in enumerate(axes):
            if j != k and _overlap(tight, other.bbox) and not _overlap(ax.bbox, other.bbox):
                problems.append(f"{name}: axes {k}'s labels lie on axes {j}")
    for legend in fig.legends:
        box = legend.get_window_extent(renderer)
        if box.y1 > page.y1 + TOLERANCE_PX or box.x0 < page.x0 - TOLERANCE_PX:
            problems.append(f"{name}: the legend runs off the figure: {box}")
        problems += [
            f"{name}: the legend lies on axes {k}"
            for k, ax in enumerate(axes)
            if _overlap(box, ax.bbox)
        ]
    return problems


def _cases(tmp_path: Path) -> dict[str, Callable[[], object]]:
    from tests.exporters.report.test_report_pdf_text import (
        _map_with_history,
        _ranging,
        _two_failing,
    )

    def summary() -> object:
        from exporters.summary.plots import render_summary_plots
        from tests.exporters.summary.test_summary import _summary, _week_runs

        return render_summary_plots(_summary(_week_runs(np.random.default_rng(5))))

    def checkpoints() -> object:
        from exporters.plots.checkpoints import plot_checkpoint_plan
        from tests.checkpoint_factory import survey_evaluation

        return plot_checkpoint_plan(survey_evaluation(np.random.default_rng(3)), 0)

    def report(result: Callable[[], EvaluationResult]) -> Callable[[], object]:
        return lambda: render_report_plots(result(), ExportOptions())

    return {
        "two estimates, a tolerance": report(_two_failing),
        "ranging": report(_ranging),
        "a map and an excursion": report(lambda: _map_with_history(tmp_path)),
        "summary": summary,
        "control points": checkpoints,
    }


@pytest.mark.parametrize(
    "case",
    [
        "two estimates, a tolerance",
        "ranging",
        "a map and an excursion",
        "summary",
        "control points",
    ],
)
def test_every_decoration_fits(case: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every figure of the case keeps its labels, notes and legend on the figure, apart."""
    figures = list(_figures(monkeypatch, _cases(tmp_path)[case]))
    assert figures
    problems = [
        p
        for name, fig in figures
        for p in (_check_kit(name, fig) if isinstance(fig, KitFigure) else _check(name, fig))
    ]
    assert problems == [], "\n".join(problems)
