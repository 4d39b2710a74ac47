"""One summary report over many recordings: the use case of ``loceval report`` and schedule runs.

Both front doors evaluate recordings with an :class:`EvaluationTemplate` and collect one
:class:`~exporters.summary.SummaryRun` per recording (a failure included, with its reason);
this module turns those runs into the summary files asked for, taking the tolerance from the
template in one place.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from loceval.evaluation import Tolerance

if TYPE_CHECKING:
    from service.schemas.schedules import EvaluationTemplate

__all__ = ["summary_files", "template_tolerance"]


def template_tolerance(template: EvaluationTemplate) -> Tolerance | None:
    """Return the template's tolerance, parsed (None: the template sets none)."""
    text = template.options.tolerance
    return Tolerance.parse(text) if text else None


def summary_files(
    template: EvaluationTemplate,
    runs: Sequence[Any],
    formats: Collection[str],
    *,
    title: str,
    selection: str,
    templates_dir: Path,
    generated_at: dt.datetime | None = None,
    notes: Sequence[str] = (),
    schedule_id: str | None = None,
    run_id: str | None = None,
) -> dict[str, bytes]:
    """Return the summary files in ``formats`` (``summary.html``, ``summary.pdf``) by name.

    Only the formats asked for are rendered: an HTML-only summary never lays out a PDF.
    """
    # exporters.summary draws with matplotlib: imported when a summary is made, not at start-up.
    from exporters.summary import SummaryInput, render_summary_files  # noqa: PLC0415

    summary = SummaryInput(
        title=title,
        generated_at=generated_at or dt.datetime.now(dt.UTC),
        selection=selection,
        runs=list(runs),
        tolerance=template_tolerance(template),
        notes=list(notes),
        schedule_id=schedule_id,
        run_id=run_id,
    )
    return render_summary_files(summary, formats, templates_dir=templates_dir)
