"""Occupancy grid maps against the building's plan: reading, fitting, measuring."""

from __future__ import annotations

from loceval.maps.evaluation import MapEvaluation, WallFigures, evaluate_map
from loceval.maps.grid import FREE, MAX_MAP_CELLS, OCCUPIED, UNKNOWN, OccupancyGrid
from loceval.maps.reading import read_map

__all__ = [
    "FREE",
    "MAX_MAP_CELLS",
    "OCCUPIED",
    "UNKNOWN",
    "MapEvaluation",
    "OccupancyGrid",
    "WallFigures",
    "evaluate_map",
    "read_map",
]
