"""The figures of one map message of a topic (:mod:`loceval.maps.history` judges them)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["MapSnapshot"]


@dataclass(frozen=True, slots=True)
class MapSnapshot:
    """The figures of one map message.

    Attributes:
        index: the message's position on its topic (0: the first).
        stamp_ns: its header stamp.
        t_s: seconds since the reference's first stamp (as ``errors.csv``), or None.
        size_cells: (columns, rows).
        wall_cells: wall cells (occupied with a free 4-neighbour).
        placed_rmse_m: wall distance RMSE as placed.
        rigid_rmse_m: after the best rigid fit.
        similarity_rmse_m: after the best similarity fit.
        similarity_scale: the similarity fit's scale.
        scale_error_pct: how much longer (+) or shorter (-) the map is than the plan.
        rigid_rotation_deg: the rigid fit's rotation (how far the map turned off).
        rigid_translation_m: the rigid fit's (x, y) translation.
        plan_coverage: share of the plan's walls seen (after the similarity fit).
        clutter_cells: cells not in the plan.
        note: why the message was not judged (then the figures are None).
    """

    index: int
    stamp_ns: int | None
    t_s: float | None
    size_cells: tuple[int, int]
    wall_cells: int | None = None
    placed_rmse_m: float | None = None
    rigid_rmse_m: float | None = None
    similarity_rmse_m: float | None = None
    similarity_scale: float | None = None
    scale_error_pct: float | None = None
    rigid_rotation_deg: float | None = None
    rigid_translation_m: tuple[float, float] | None = None
    plan_coverage: float | None = None
    clutter_cells: int | None = None
    note: str | None = None

    def to_dict(self) -> dict[str, object]:
        """Return the record of the result document's ``map.history``."""
        return {
            "index": self.index,
            "t_s": self.t_s,
            "size_cells": list(self.size_cells),
            "wall_cells": self.wall_cells,
            "placed_rmse_m": self.placed_rmse_m,
            "rigid_rmse_m": self.rigid_rmse_m,
            "similarity_rmse_m": self.similarity_rmse_m,
            "similarity_scale": self.similarity_scale,
            "scale_error_pct": self.scale_error_pct,
            "rigid_rotation_deg": self.rigid_rotation_deg,
            "rigid_translation_m": (
                None if self.rigid_translation_m is None else list(self.rigid_translation_m)
            ),
            "plan_coverage": self.plan_coverage,
            "clutter_cells": self.clutter_cells,
            "note": self.note,
        }
