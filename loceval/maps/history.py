"""The map's figures over time: each ``OccupancyGrid`` message of a bag topic, judged.

A SLAM system publishes its map again and again while it drives; the last message is the
map it ended with and is judged in full (:func:`~loceval.maps.evaluation.evaluate_map`).
Every earlier message is judged the same way, against the same plan and placement, and
only its figures are kept (:class:`MapSnapshot`): whether the map bent or shrank while it
grew, and when. At most :data:`MAX_MAP_MESSAGES` messages are judged; a topic with more is
subsampled evenly (the first and the last kept) and the result says so. A message that
cannot be judged (an early map with no wall yet, no overlap with the plan) is listed with
the reason instead of stopping the evaluation; only the last message's problems stop it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Final

from loceval.core.arrays import FloatArray
from loceval.core.geometry import SimilarityTransform
from loceval.errors import InputError, MetricError, ReaderError
from loceval.maps.evaluation import MapEvaluation, evaluate_map
from loceval.maps.grid import OccupancyGrid
from loceval.maps.reading import iter_bag_maps, read_map, split_bag_source
from loceval.maps.snapshot import MapSnapshot

__all__ = ["MAX_MAP_MESSAGES", "MapSnapshot", "evaluate_map_source"]

MAX_MAP_MESSAGES: Final = 30
"""Most messages of a map topic judged; more are subsampled evenly (last kept)."""
_NS_PER_S: Final = 1_000_000_000


def _judged(
    index: int, t0_ns: int | None, found: MapEvaluation, grid: OccupancyGrid
) -> MapSnapshot:
    """Return the figures of a judged message."""
    rigid = found.rigid[0]
    return MapSnapshot(
        index=index,
        stamp_ns=grid.stamp_ns,
        t_s=_seconds(grid.stamp_ns, t0_ns),
        size_cells=(grid.shape[1], grid.shape[0]),
        wall_cells=len(found.cells_xy),
        placed_rmse_m=found.placed.rmse,
        rigid_rmse_m=found.rigid[1].rmse,
        similarity_rmse_m=found.similarity[1].rmse,
        similarity_scale=found.similarity[0].scale,
        scale_error_pct=found.scale_error_pct,
        rigid_rotation_deg=math.degrees(rigid.rotation_rad),
        rigid_translation_m=rigid.translation_m,
        plan_coverage=found.similarity[1].plan_coverage,
        clutter_cells=found.clutter_cells,
    )


def _seconds(stamp_ns: int | None, t0_ns: int | None) -> float | None:
    if stamp_ns is None or t0_ns is None:
        return None
    return (stamp_ns - t0_ns) / _NS_PER_S


def evaluate_map_source(
    source: str,
    plan_segments: FloatArray,
    placement: SimilarityTransform,
    *,
    thresholds_m: Sequence[float] = (0.05, 0.10, 0.15),
    clutter_m: float = 0.5,
    estimate: str | None = None,
    t0_ns: int | None = None,
    display: str | None = None,
    max_messages: int = MAX_MAP_MESSAGES,
) -> MapEvaluation:
    """Read a map source and measure it against the plan; a bag topic message by message.

    A map file (``map.yaml``, a zip) is one map. A ``BAG@TOPIC`` source is judged at each
    of its messages (at most ``max_messages``, evenly spread), the last in full; the
    figures of each are the result's ``history``.

    Args:
        source: ``map.yaml``, ``map.zip`` or ``BAG@TOPIC``.
        plan_segments: (K, 2, 2) the plan's walls in the evaluation frame, metres.
        placement: map frame -> evaluation frame.
        thresholds_m: the share-within thresholds.
        clutter_m: the clutter distance, metres.
        estimate: the estimate whose alignment placed the map.
        t0_ns: the reference's first stamp (the history's times are seconds since it).
        display: the map's name in messages and the result instead of its path.
        max_messages: the most messages judged.

    Raises:
        InputError, ReaderError, MetricError: the map (its last message) is unreadable,
            has no wall or does not overlap the plan.
    """

    def judge(grid: OccupancyGrid) -> MapEvaluation:
        if display is not None:
            grid = replace(grid, source=display)
        return evaluate_map(
            grid,
            plan_segments,
            placement,
            thresholds_m=thresholds_m,
            clutter_m=clutter_m,
            estimate=estimate,
        )

    in_bag = split_bag_source(source)
    if in_bag is None:
        return judge(read_map(source))
    history: list[MapSnapshot] = []
    last: tuple[int, int, OccupancyGrid] | None = None
    for index, total, grid in iter_bag_maps(Path(in_bag[0]), in_bag[1], limit=max_messages):
        if last is not None:  # every message but the last: its figures only
            history.append(_snapshot(last[0], last[2], judge, t0_ns))
        last = (index, total, grid)
    if last is None:  # pragma: no cover  (iter_bag_maps raises on an empty topic)
        msg = f"{source}: the topic holds no map message."
        raise ReaderError(msg, option="map")
    index, total, grid = last
    found = judge(grid)
    history.append(_judged(index, t0_ns, found, grid))
    note = None
    if total > len(history):
        note = (
            f"The topic holds {total} map messages; {len(history)} of them, evenly spread "
            f"(the first and the last among them), were judged for the figures over time."
        )
    return replace(found, history=tuple(history), history_note=note)


def _snapshot(
    index: int,
    grid: OccupancyGrid,
    judge: Callable[[OccupancyGrid], MapEvaluation],
    t0_ns: int | None,
) -> MapSnapshot:
    """Judge one earlier message; a map that cannot be judged yet is listed with the reason."""
    try:
        found = judge(grid)
    except (InputError, MetricError) as err:
        return MapSnapshot(
            index=index,
            stamp_ns=grid.stamp_ns,
            t_s=_seconds(grid.stamp_ns, t0_ns),
            size_cells=(grid.shape[1], grid.shape[0]),
            note=str(err),
        )
    return _judged(index, t0_ns, found, grid)
