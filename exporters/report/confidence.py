"""How sure the report's figures are: intervals in Tables 1-2, comparisons, NEES table.

The evaluation's :class:`~loceval.assessment.assess.Assessment` of each estimate and its
comparisons, formatted for the templates: the 95 % interval after each RMSE, mean and
median of Tables 1-2 ("0.194 m (0.180-0.210)"), every comparison of two estimates as a
sentence for the verdict section, and the consistency (NEES) of a reported covariance.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from loceval.evaluation import EvaluationResult, Verdict

__all__ = ["ConfidenceView", "ConsistencyRow", "build_confidence_view", "undecided_headline"]

_TABLES = {
    (1, "translation"): "ate_translation",
    (1, "rotation"): "ate_rotation",
    (2, "translation"): "rpe_translation",
    (2, "rotation"): "rpe_rotation",
}
"""Table number and row group -> the series whose intervals it shows."""
_ROWS = {"RMSE": "rmse", "MEAN": "mean", "MEDIAN": "median"}
"""Table rows with an interval -> the interval's key."""


@dataclass(frozen=True, slots=True)
class ConsistencyRow:
    """One block's NEES of one estimate, formatted."""

    name: str
    block: str
    dof: str
    mean: str
    band: str
    share_in_band: str
    verdict: str


@dataclass(frozen=True, slots=True)
class ConfidenceView:
    """The report's intervals, comparisons and consistency, formatted.

    Attributes:
        intervals: ``"table/group/ROW"`` -> per estimate the text after the value
            (`` (0.180-0.210)``, or "" without an interval).
        note: how the intervals were found, or that they were turned off.
        comparisons: one sentence per comparison of two estimates.
        consistency: NEES rows of the estimates that report a covariance.
    """

    intervals: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    note: str = ""
    comparisons: tuple[str, ...] = ()
    consistency: tuple[ConsistencyRow, ...] = ()

    def suffix(self, table: int, group: str, label: str, column: int) -> str:
        """Return the interval text after a Table 1-2 cell, or ""."""
        texts = self.intervals.get(f"{table}/{group}/{label}", ())
        return texts[column] if column < len(texts) else ""


def _name(result: EvaluationResult, k: int) -> str:
    return result.estimates[k].name or f"estimate {k + 1}"


def build_confidence_view(result: EvaluationResult) -> ConfidenceView:
    """Return the formatted intervals, comparisons and NEES of an evaluation."""
    intervals: dict[str, tuple[str, ...]] = {}
    for (table, group), series in _TABLES.items():
        for label, key in _ROWS.items():
            texts = []
            for e in result.estimates:
                found = None if e.assessment is None else e.assessment.intervals.get(series)
                lo, hi = (None, None) if found is None else found.ci95[key]
                texts.append("" if lo is None else f" ({lo:.3f}–{hi:.3f})")
            intervals[f"{table}/{group}/{label}"] = tuple(texts)
    if result.config.no_ci:
        note = "Confidence intervals were turned off for this evaluation."
    else:
        note = (
            "In brackets: the 95 % confidence interval (moving-block bootstrap, which keeps "
            "the errors' correlation along the path; seeded, so reruns agree)."
        )
    rows = []
    for k, e in enumerate(result.estimates):
        nees_of = None if e.assessment is None else e.assessment.consistency
        if nees_of is None:
            continue
        blocks = (("position", nees_of.nees_position), ("rotation", nees_of.nees_rotation))
        for block, nees in blocks:
            if nees is None:
                continue
            lo, hi = nees.band95
            rows.append(
                ConsistencyRow(
                    name=_name(result, k),
                    block=block,
                    dof=str(nees.dof),
                    mean=f"{nees.mean:.2f}",
                    band=f"{lo:.2f}–{hi:.2f}",
                    share_in_band=f"{nees.share_in_band * 100:.1f} %",
                    verdict=nees.verdict.value,
                )
            )
    return ConfidenceView(
        intervals=intervals,
        note=note,
        comparisons=tuple(c.summary for c in result.comparisons or ()),
        consistency=tuple(rows),
    )


def undecided_headline(name: str, verdict: Verdict) -> str:
    """Return the headline of a verdict whose interval straddles the requirement."""
    tol = verdict.tolerance
    lo, hi = verdict.share_ci95 or (verdict.share_within, verdict.share_within)
    return (
        f"{name}: undecided: {verdict.share_within * 100:.1f} % of its poses are within "
        f"{tol.distance_m:g} m of the ground truth (95 % interval {lo * 100:.1f}–"
        f"{hi * 100:.1f} %, {tol.share * 100:g} % required); the interval straddles the "
        "requirement, so this run cannot tell whether it meets it: record a longer run."
    )
