"""The report's verdict section: each estimate's verdict in words, its stretches and rooms.

:func:`verdict_view` words one estimate's verdict for a non-expert (pass, fail or
undecided, the share within the tolerance, where the path goes beyond it, in which rooms);
:func:`building_view` states the building model the paths were placed on and what is wrong
with how it is placed. The report's view model (:mod:`exporters.report.view`) holds them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from exporters.colours import estimate_colour
from exporters.plots import MAX_SPAN_MARKERS
from exporters.report.confidence import undecided_headline
from exporters.report.provenance import estimate_name, format_xyz
from loceval.assessment.verdict import FailingSpan
from loceval.core.lengths import length_unit
from loceval.evaluation import EvaluationResult

__all__ = ["BuildingView", "SpanView", "VerdictView", "building_view", "verdict_view"]


@dataclass(frozen=True, slots=True)
class SpanView:
    """A stretch of the path beyond the tolerance, as the verdict lists it.

    ``words`` says it as a site engineer would ("beyond 0.025 m for 4.1 s in 2.14 Office");
    ``space`` is the building's room it lies in ("" when the model names none there);
    ``max_error_m`` is in the verdict's :attr:`VerdictView.error_unit`.
    """

    number: int
    start_s: str
    end_s: str
    duration_s: str
    poses: int
    max_error_m: str
    where: str
    length_m: str = ""
    space: str = ""
    words: str = ""


@dataclass(frozen=True, slots=True)
class VerdictView:
    """One estimate's verdict in words."""

    name: str
    colour: str
    status: str  # "pass", "fail", "undecided" or "none"
    badge: str
    headline: str
    details: tuple[str, ...]
    spans: tuple[SpanView, ...]
    spans_total: int
    map_figure: int | None
    shares: str
    glance: str
    error_unit: str = "m"
    """The unit of the stretches' largest errors (one group: :mod:`loceval.core.lengths`)."""
    spaces: bool = False
    """Whether the building names the space of any stretch (the table's room column)."""
    figures: str = ""
    """The verdict's figures in one line: ``87.2 % within 0.1 m (95 % interval 85.0–89.1 %,
    95 % required)`` ("" without a tolerance)."""


@dataclass(frozen=True, slots=True)
class BuildingView:
    """The building model the paths were placed on, as the report states it.

    Attributes:
        source: the model's file name.
        spaces: how many named spaces it has, and how they were read ("" without).
        warnings: what is wrong with how it is placed, and what to set.
    """

    source: str
    spaces: str
    warnings: tuple[str, ...]


def verdict_view(result: EvaluationResult, k: int, map_figure: int | None) -> VerdictView:
    """Return estimate ``k``'s verdict in words, its worst stretches and their rooms.

    Args:
        result: the evaluation (placed on its building, when it has one).
        k: which estimate.
        map_figure: the number of its error map, where the stretches are numbered.
    """
    e = result.estimates[k]
    name = estimate_name(e, k)
    colour = estimate_colour(k)
    ate = e.ate_translation
    shares = " · ".join(f"{share * 100:.1f} % within {t:g} m" for t, share in e.within.items())
    worst = e.worst[0] if e.worst else None
    worst_text = (
        ""
        if worst is None
        else (
            f"The largest error is {length_unit([worst.error]).text(worst.error)}, "
            f"{worst.t_s:.1f} s into the recording "
            f"at x, y, z = {format_xyz(worst.position_xyz)} m."
        )
    )
    verdict = e.verdict
    if verdict is None:
        return VerdictView(
            name=name,
            colour=colour,
            status="none",
            badge="NO VERDICT",
            headline=(
                f"{name}: typical error (RMSE) {ate.stats.rmse:.3f} m over "
                f"{len(ate):,} poses; no tolerance to judge it against."
            ),
            details=(worst_text,) if worst_text else (),
            spans=(),
            spans_total=0,
            map_figure=None,
            shares=shares,
            glance=f"typical error (RMSE) {ate.stats.rmse:.3f} m; {shares}",
        )
    tol = verdict.tolerance
    share_pct = verdict.share_within * 100
    interval = ""
    if verdict.share_ci95 is not None:
        lo, hi = verdict.share_ci95
        interval = f"95 % interval {lo * 100:.1f}–{hi * 100:.1f} %, "
    figures = (
        f"{share_pct:.1f} % within {tol.distance_m:g} m ({interval}{tol.share * 100:g} % required)"
    )
    if verdict.passed:
        headline = (
            f"{name} meets the tolerance: {share_pct:.1f} % of its poses are within "
            f"{tol.distance_m:g} m of the ground truth ({tol.share * 100:g} % required)."
        )
    elif verdict.result == "undecided":
        headline = undecided_headline(name, verdict)
    else:
        headline = (
            f"{name} does not meet the tolerance: only {share_pct:.1f} % of its poses are "
            f"within {tol.distance_m:g} m of the ground truth ({tol.share * 100:g} % required)."
        )
    details: list[str] = []
    spans = verdict.failing_spans
    if spans:
        over = sum(s.poses for s in spans)
        where = (
            f" The worst are listed below and numbered on its map (Figure {map_figure})."
            if map_figure is not None
            else " The worst are listed below."
        )
        details.append(
            f"Its error exceeds {tol.distance_m:g} m in {len(spans):,} "
            f"stretch{'es' if len(spans) != 1 else ''} of the path, {over:,} of "
            f"{len(ate):,} poses ({100.0 * over / max(len(ate), 1):.1f} %).{where}"
        )
        rooms = _by_room(spans)
        if rooms:
            details.append(f"Where, in the building: {rooms}.")
    else:
        details.append(f"Its error never exceeds {tol.distance_m:g} m.")
    if worst_text:
        details.append(worst_text)
    shown = spans[:MAX_SPAN_MARKERS]
    unit = length_unit(s.max_error_m for s in shown)
    span_views = tuple(
        SpanView(
            number=n,
            start_s=f"{s.start_s:.2f}",
            end_s=f"{s.end_s:.2f}",
            duration_s=f"{s.duration_s:.2f}",
            poses=s.poses,
            max_error_m=unit.format(s.max_error_m),
            where=format_xyz(s.max_error_position_xyz),
            length_m=f"{s.length_m:.1f}",
            space=s.space or "",
            words=s.words(tol.distance_m),
        )
        for n, s in enumerate(shown, start=1)
    )
    return VerdictView(
        name=name,
        colour=colour,
        status=verdict.result,
        badge=verdict.result.upper(),
        headline=headline,
        details=tuple(details),
        spans=span_views,
        spans_total=len(spans),
        map_figure=map_figure,
        shares=shares,
        glance=(
            f"{share_pct:.1f} % of poses within {tol.distance_m:g} m "
            f"({tol.share * 100:g} % required)"
        ),
        error_unit=unit.symbol,
        spaces=any(v.space for v in span_views),
        figures=figures,
    )


def _by_room(spans: Sequence[FailingSpan]) -> str:
    """Return the rooms of the stretches, the longest time beyond first ("" without rooms)."""
    seconds: dict[str, float] = {}
    counts: dict[str, int] = {}
    for s in spans:  # one per stretch
        if s.space is None:
            continue
        seconds[s.space] = seconds.get(s.space, 0.0) + s.duration_s
        counts[s.space] = counts.get(s.space, 0) + 1
    parts = [
        f"{room} ({counts[room]} stretch{'es' if counts[room] != 1 else ''}, {seconds[room]:.1f} s)"
        for room in sorted(seconds, key=lambda r: -seconds[r])
    ]
    outside = sum(1 for s in spans if s.space is None)
    if parts and outside:
        parts.append(f"{outside} outside the named spaces")
    return "; ".join(parts)


def building_view(result: EvaluationResult) -> BuildingView | None:
    """Return the building model the paths were placed on, or None without one."""
    building = result.building
    if building is None:
        return None
    count = len(building.spaces)
    spaces = (
        f"{count} named space{'s' if count != 1 else ''} ({building.spaces_from})" if count else ""
    )
    return BuildingView(source=building.source, spaces=spaces, warnings=building.warnings)
