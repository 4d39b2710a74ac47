"""Inspect the tables of a radio system: anchors (``id,x,y,z``) and ranges (no trajectory)."""

from __future__ import annotations

from loceval.inspection.model import Inspection
from loceval.readers import SourceSpec
from loceval.readers.radio import read_anchors, read_ranges_overview

__all__ = ["inspect_anchors", "inspect_ranges"]


def inspect_anchors(spec: SourceSpec) -> Inspection:
    """Describe an anchors table: the anchor ids in file order.

    Raises:
        ReaderError: the table cannot be read (see :func:`loceval.readers.radio.read_anchors`).
    """
    anchors = read_anchors(spec.path)
    return Inspection(
        path=str(spec.path),
        kind="anchors",
        format="anchors",
        sources=(),
        anchor_ids=anchors.ids,
    )


def inspect_ranges(spec: SourceSpec) -> Inspection:
    """Describe a ranges table: its rows and the anchor ids it names.

    Raises:
        ReaderError: the table has no header or lacks a column, or its time unit is unknown.
    """
    overview = read_ranges_overview(spec.path)
    return Inspection(
        path=str(spec.path),
        kind="ranges",
        format="ranges",
        sources=(),
        anchor_ids=overview.anchor_ids,
        range_count=overview.rows,
    )
