"""The report of an evaluation against control points (``report.html`` / ``report.pdf``).

One section per estimate: the plan view with the error arrows (scaled, the scale shown),
the statistics over the scored visits, the Hilti and LaMAria scores, the recall per
threshold, a table per control point and the lists of unvisited points and unmatched stops.
The templates are ``templates/checkpoints.html.j2`` (it shares ``report.css``) and, for the
PDF, ``templates/checkpoints.typ`` (Typst, the same view model).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final, cast

import numpy as np

from exporters.options import ExportOptions
from exporters.report.render import (
    DEFAULT_TEMPLATES_DIR,
    check_pdf,
    check_templates,
    layout_pdf,
    pdf_figure_format,
    render_template,
)
from exporters.viewer.checkpoints import checkpoint_scene
from exporters.viewer.page import scene_fragment
from loceval.checkpoint_evaluation import CheckpointEstimate, CheckpointEvaluation

if TYPE_CHECKING:
    from exporters.plots.figure import ImageFormat
    from loceval.core.arrays import FloatArray

__all__ = [
    "CHECKPOINT_PDF_TEMPLATE",
    "CHECKPOINT_TEMPLATE",
    "CheckpointReportView",
    "EstimateSection",
    "build_checkpoint_view",
    "render_checkpoint_report",
]

CHECKPOINT_TEMPLATE: Final = "checkpoints.html.j2"
CHECKPOINT_PDF_TEMPLATE: Final = "checkpoints.typ"
_STATS: Final = (("RMSE", "rmse"), ("MEAN", "mean"), ("MEDIAN", "median"), ("STD", "std"),
                 ("MIN", "min"), ("MAX", "max"))  # fmt: skip


@dataclass(frozen=True, slots=True)
class EstimateSection:
    """What the report shows of one estimate (texts ready to print).

    Attributes:
        name: the estimate's name.
        alignment: the alignment in words.
        counts: visits scored, visits fixing the alignment, points unvisited, in words.
        figure: the plan view (a ``data:`` URI), its title and caption.
        stats: (label, value) rows over the scored visits' 3D error.
        scores: (label, value) rows: Hilti, LaMAria and the recall per threshold.
        points: one row per control point: id, visits, mean / max 3D, mean horizontal,
            mean vertical error, and whether it fixed the alignment.
        unvisited: ids of points never visited.
        unmatched: the stops near no control point, in words.
    """

    name: str
    alignment: str
    counts: str
    figure: tuple[str, str, str]
    stats: tuple[tuple[str, str], ...]
    scores: tuple[tuple[str, str], ...]
    points: tuple[tuple[str, ...], ...]
    unvisited: tuple[str, ...]
    unmatched: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class CheckpointReportView:
    """The template's variables.

    Attributes:
        title: the report's title.
        summary: one sentence for the top of the page.
        created_at: when the evaluation ran.
        evaluation_id: the evaluation's id.
        loceval_version: the version that made it.
        reference: (label, value) facts about the survey.
        estimates: one section per estimate.
        warnings: (about, message) pairs.
    """

    title: str
    summary: str
    created_at: str
    evaluation_id: str
    loceval_version: str
    reference: tuple[tuple[str, str], ...]
    estimates: tuple[EstimateSection, ...]
    warnings: tuple[tuple[str, str], ...]


def _mm(value: float) -> str:
    return f"{value * 1000:.1f} mm"


def _point_rows(entry: CheckpointEstimate, ids: Sequence[str]) -> tuple[tuple[str, ...], ...]:
    visits = entry.result.visits
    by_id = {pid: [v for v in visits if v.point_id == pid] for pid in ids}
    rows = []
    for pid in ids:  # one row per control point (tens to hundreds)
        mine = by_id[pid]
        if not mine:
            rows.append((pid, "0", "-", "-", "-", "-", ""))
            continue
        e3 = np.array([v.error_m for v in mine])
        rows.append(
            (
                pid,
                str(len(mine)),
                _mm(float(e3.mean())),
                _mm(float(e3.max())),
                _mm(float(np.mean([v.error_h_m for v in mine]))),
                f"{np.mean([v.error_v_m for v in mine]) * 1000:+.1f} mm",
                "yes" if any(v.used_for_alignment for v in mine) else "",
            )
        )
    return tuple(rows)


def _section(
    evaluation: CheckpointEvaluation,
    index: int,
    image_format: str,
    floor_plan: FloatArray | None = None,
) -> EstimateSection:
    from exporters.plots.checkpoints import plot_checkpoint_plan  # noqa: PLC0415

    entry = evaluation.estimates[index]
    result = entry.result
    doc = cast("dict[str, Any]", result.to_dict()["checkpoints"])
    fmt: ImageFormat = "png" if image_format == "png" else "svg"
    plot = plot_checkpoint_plan(evaluation, index, formats=(fmt,), floor_plan=floor_plan)
    stats = result.stats
    scores = [("Hilti 2023 score", f"{doc['score']['hilti']:.1f} %"),
              ("LaMAria score", f"{doc['score']['lamaria']:.1f} %")]  # fmt: skip
    scores += [
        (f"recall within {t} m", f"{share * 100:.1f} % of points")
        for t, share in doc["recall"].items()
    ]
    fixed = len(result.visits) - len(result.scored)
    transform = result.transform
    alignment = result.method.value
    if not transform.is_rigid:
        alignment += f" (scale {transform.scale:.4f})"
    return EstimateSection(
        name=entry.name,
        alignment=alignment,
        counts=(
            f"{len(result.scored)} visits scored, {fixed} fixed the alignment, "
            f"{len(result.unvisited)} of {len(evaluation.points)} points never visited"
        ),
        figure=(plot.data_uri(fmt), plot.title, plot.caption),
        stats=tuple((label, _mm(float(getattr(stats, key)))) for label, key in _STATS),
        scores=tuple(scores),
        points=_point_rows(entry, evaluation.points.ids),
        unvisited=result.unvisited,
        unmatched=tuple(
            f"{s.start_ns / 1e9:.3f}-{s.end_ns / 1e9:.3f} s at "
            f"({s.position_xyz[0]:.3f}, {s.position_xyz[1]:.3f}, {s.position_xyz[2]:.3f}) m"
            for s in result.unmatched_stops
        ),
    )


def build_checkpoint_view(
    evaluation: CheckpointEvaluation, options: ExportOptions, *, image_format: str = "svg"
) -> CheckpointReportView:
    """Return the report's variables (the plan views encoded as ``image_format``)."""
    points = evaluation.points
    extent = points.positions_xyz.max(axis=0) - points.positions_xyz.min(axis=0)
    from exporters.plots.checkpoints import device_heights_m  # noqa: PLC0415
    from exporters.plots.underlay import floor_plan_segments  # noqa: PLC0415

    floor_plan = floor_plan_segments(device_heights_m(evaluation), options)  # once
    sections = tuple(
        _section(evaluation, k, image_format, floor_plan) for k in range(len(evaluation.estimates))
    )
    scored = "; ".join(
        f"{s.name}: Hilti {s.scores[0][1]}, LaMAria {s.scores[1][1]}" for s in sections
    )
    summary = (
        f"{len(sections)} estimate(s) scored at {len(points)} surveyed control points. {scored}."
    )
    warnings = [("reference", w) for w in points.warnings]
    warnings += [(e.name, w) for e in evaluation.estimates for w in e.estimate.warnings]
    warnings += [(e.name, w) for e in evaluation.estimates for w in e.result.warnings]
    return CheckpointReportView(
        title=options.title or f"{evaluation.reference_name}: control points",
        summary=summary,
        created_at=evaluation.created_at,
        evaluation_id=options.evaluation_id or "-",
        loceval_version=evaluation.loceval_version,
        reference=(
            ("Survey", points.source),
            ("Points", str(len(points))),
            ("Extent", " x ".join(f"{e:.2f}" for e in extent) + " m"),
            ("Smallest spacing", f"{points.min_spacing_m():.3f} m"),
            ("Survey sigma", "given" if points.sigma_xyz is not None else "not given"),
            ("Visits", evaluation.visits_source),
        ),
        estimates=sections,
        warnings=tuple(warnings),
    )


def render_checkpoint_report(
    evaluation: CheckpointEvaluation, options: ExportOptions, *, pdf: bool
) -> tuple[bytes, bytes | None]:
    """Render ``report.html`` (SVG plots) and, with ``pdf``, ``report.pdf``.

    The PDF is typeset by Typst from the HTML's view model, its plots as vectors (for a
    folder of HTML templates only, WeasyPrint lays out the HTML with PNG plots).

    Raises:
        ExportUnavailableError: Jinja2, matplotlib or the PDF's engine is missing.
        ExportError: the templates are missing or the layout failed.
    """
    folder = options.templates_dir or DEFAULT_TEMPLATES_DIR
    check_templates(folder, CHECKPOINT_TEMPLATE, label="control-point report")
    if pdf:
        check_pdf(folder, CHECKPOINT_PDF_TEMPLATE)

    def render_html(view: CheckpointReportView, *, interactive: bool) -> bytes:
        return render_template(
            folder,
            CHECKPOINT_TEMPLATE,
            label="control-point report",
            requirement="report.html",
            report=view,
            # the interactive section is the HTML's only (the PDF keeps its figures)
            viewer=scene_fragment(checkpoint_scene(evaluation, options), folder)
            if interactive
            else None,
        )

    view = build_checkpoint_view(evaluation, options, image_format="svg")
    html = render_html(view, interactive=True)
    if not pdf:
        return html, None
    if pdf_figure_format(folder, CHECKPOINT_PDF_TEMPLATE) != "svg":
        view = build_checkpoint_view(evaluation, options, image_format="png")
    return html, layout_pdf(
        folder,
        CHECKPOINT_PDF_TEMPLATE,
        view,
        label="control-point report",
        html=lambda: render_html(view, interactive=False),
    )
