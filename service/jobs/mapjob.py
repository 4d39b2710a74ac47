"""The map step of an evaluation job: the robot's map against the building plan.

Run by :func:`service.jobs.runner.run_job` after the trajectories are evaluated, the same way for
the CLI (``--map SOURCE --building PLAN``) and the API (``options.map``): the plan is the
building model cut at the reference's median height (:mod:`exporters.plots.underlay`,
placed by the site transform), the map is placed by the chosen estimate's alignment; a bag
topic's messages are judged one by one (:mod:`loceval.maps.history`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING

from loceval.errors import InputError

if TYPE_CHECKING:
    from exporters.options import ExportOptions
    from loceval.evaluation import EvaluationResult
    from loceval.maps import MapEvaluation

__all__ = ["MapSource", "measure_map"]


@dataclass(frozen=True, slots=True)
class MapSource:
    """What the map step needs.

    Attributes:
        source: ``map.yaml``, ``map.zip`` or ``BAG@TOPIC``.
        plan: the building model and its placement options (``building`` set).
        estimate: the name of the estimate whose alignment places the map (None: the first).
        clutter_m: the clutter distance, metres.
        display: the name shown for the map instead of its path on the server.
    """

    source: str
    plan: ExportOptions
    estimate: str | None = None
    clutter_m: float = 0.5
    display: str | None = None


def map_source(
    source: str | os.PathLike[str] | None,
    plan: ExportOptions | None,
    *,
    estimate: str | None,
    clutter_m: float,
    display: str | None = None,
) -> MapSource | None:
    """Check the map options together: a map needs a plan; an estimate name needs a map.

    ``source`` is read the same way from both front doors: the CLI's ``--map`` (a path,
    ``run.mcap@/map`` included) and the API's dataset file with its selector, both as text
    (:func:`loceval.maps.reading.split_bag_source` tells a file from ``BAG@TOPIC``).

    Raises:
        InputError: a map without a building plan, or a map estimate without a map.
    """
    if source is None:
        if estimate is not None:
            msg = "The estimate placing the map applies only with a map; give the map too."
            raise InputError(msg, option="map_estimate")
        return None
    if plan is None or plan.building is None:
        msg = (
            "A map is measured against the building's plan; give the plan too (the CLI: "
            "--building PLAN.dxf or a model to cut; the API: options.building)."
        )
        raise InputError(msg, option="map")
    return MapSource(os.fspath(source), plan, estimate, clutter_m, display)


def measure_map(result: EvaluationResult, source: MapSource) -> MapEvaluation:
    """Read the map and the plan and measure one against the other.

    Raises:
        InputError: no estimate of that name, an unreadable map or plan, no overlap.
    """
    from exporters.plots.underlay import floor_plan_segments  # noqa: PLC0415  (CAD)
    from loceval.maps import evaluate_map_source  # noqa: PLC0415

    names = [e.name for e in result.estimates]
    chosen = result.estimates[0]
    if source.estimate is not None:
        found = [e for e in result.estimates if e.name == source.estimate]
        if not found:
            msg = (
                f"No estimate is named {source.estimate!r} to place the map; the estimates "
                f"are {', '.join(map(repr, names))}."
            )
            raise InputError(msg, option="map_estimate")
        chosen = found[0]
    segments = floor_plan_segments(result.reference.positions_xyz[:, 2], source.plan)
    if segments is None or not len(segments):
        msg = "The building plan has no wall at the device's height; check the plan."
        raise InputError(msg, option="building")
    reference = result.reference.stamps_ns
    return evaluate_map_source(
        source.source,
        segments,
        chosen.alignment.transform,
        thresholds_m=result.config.thresholds_m,
        clutter_m=source.clutter_m,
        estimate=chosen.name,
        t0_ns=int(reference[0]) if len(reference) else None,
        display=source.display,
    )
