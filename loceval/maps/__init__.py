"""Occupancy grid maps against the building's plan: reading, fitting, measuring."""

from __future__ import annotations

from loceval.maps.evaluation import MapEvaluation, WallFigures, evaluate_map
from loceval.maps.grid import FREE, MAX_MAP_CELLS, OCCUPIED, UNKNOWN, OccupancyGrid
from loceval.maps.history import MAX_MAP_MESSAGES, MapSnapshot, evaluate_map_source
from loceval.maps.reading import read_map

__all__ = [
    "FREE",
    "MAX_MAP_CELLS",
    "MAX_MAP_MESSAGES",
    "OCCUPIED",
    "UNKNOWN",
    "MapEvaluation",
    "MapSnapshot",
    "OccupancyGrid",
    "WallFigures",
    "evaluate_map",
    "evaluate_map_source",
    "read_map",
]
