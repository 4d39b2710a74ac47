"""Occupancy grid maps: the map a SLAM system built, as free, occupied and unknown cells.

An :class:`OccupancyGrid` holds one state per cell (:data:`UNKNOWN`, :data:`FREE`,
:data:`OCCUPIED`) in ROS's layout: row 0 is the row at the origin (lowest y of the map
frame), column 0 the column at the origin; the origin is the corner of cell (0, 0) in the
map frame and may be turned by a yaw, as ``nav_msgs/msg/OccupancyGrid`` and map_server's
``origin: [x, y, yaw]`` give it.

:mod:`loceval.maps.reading` reads the files (map_server's YAML with its PGM or PNG, a zip
of both, a bag topic); this module is the value type and the cells' geometry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from loceval.core.arrays import BoolArray, FloatArray
from loceval.errors import InputError

__all__ = [
    "FREE",
    "MAX_MAP_CELLS",
    "OCCUPIED",
    "UNKNOWN",
    "OccupancyGrid",
    "check_map_size",
]

UNKNOWN: Final = -1
FREE: Final = 0
OCCUPIED: Final = 1
MAX_MAP_CELLS: Final = 100_000_000
"""Most cells of a map (10,000 x 10,000: 1 km square at 1 dm). A larger declared size is
refused before anything is allocated: the evaluation keeps a few arrays of that size."""


def check_map_size(width: int, height: int, *, where: str) -> None:
    """Refuse a declared map size that is empty or larger than :data:`MAX_MAP_CELLS`.

    Raises:
        InputError: the size is not positive or over the limit; the message names the map.
    """
    if width <= 0 or height <= 0:
        msg = f"{where}: the map declares {width} x {height} cells; a map needs at least one."
        raise InputError(msg, option="map")
    if width * height > MAX_MAP_CELLS:
        msg = (
            f"{where}: the map declares {width} x {height} cells ({width * height:,}), more "
            f"than the {MAX_MAP_CELLS:,} loceval evaluates; crop it to the area driven or save "
            "it at a coarser resolution."
        )
        raise InputError(msg, option="map")


@dataclass(frozen=True, slots=True, eq=False)
class OccupancyGrid:
    """A 2D occupancy grid map.

    Attributes:
        states: (H, W) int8 cell states: -1 unknown, 0 free, 1 occupied; row 0 at the origin.
        resolution_m: the side of a cell, metres.
        origin_xy: the map frame's coordinates of the outer corner of cell (0, 0), metres.
        origin_yaw_rad: the grid's rotation in the map frame, radians counter-clockwise.
        source: where it was read from (for messages and the report).
        stamp_ns: the message's stamp for a bag topic, else None.
    """

    states: NDArray[np.int8]
    resolution_m: float
    origin_xy: tuple[float, float] = (0.0, 0.0)
    origin_yaw_rad: float = 0.0
    source: str = ""
    stamp_ns: int | None = None

    def __post_init__(self) -> None:
        """Copy the states read-only and check the geometry."""
        states = np.array(self.states, dtype=np.int8)
        if states.ndim != 2:
            msg = f"An occupancy grid needs (H, W) states, got shape {states.shape!r}."
            raise InputError(msg, option="map")
        check_map_size(states.shape[1], states.shape[0], where=self.source or "map")
        values = (self.resolution_m, *self.origin_xy, self.origin_yaw_rad)
        if not all(math.isfinite(v) for v in values) or self.resolution_m <= 0:
            msg = (
                f"{self.source or 'map'}: resolution {self.resolution_m!r} and origin "
                f"{self.origin_xy!r} must be finite and the resolution positive; check the "
                "map's YAML or message."
            )
            raise InputError(msg, option="map")
        states.flags.writeable = False
        object.__setattr__(self, "states", states)
        object.__setattr__(self, "origin_xy", (float(self.origin_xy[0]), float(self.origin_xy[1])))

    @property
    def shape(self) -> tuple[int, int]:
        """Return (rows, columns)."""
        return (int(self.states.shape[0]), int(self.states.shape[1]))

    def wall_mask(self) -> BoolArray:
        """Return the wall cells: occupied cells with a free 4-neighbour (what the robot saw).

        Returns:
            (H, W) bool.
        """
        free = self.states == FREE
        near_free = np.zeros_like(free)
        near_free[1:, :] |= free[:-1, :]
        near_free[:-1, :] |= free[1:, :]
        near_free[:, 1:] |= free[:, :-1]
        near_free[:, :-1] |= free[:, 1:]
        out: BoolArray = (self.states == OCCUPIED) & near_free
        return out

    def cell_centres(self, rows: NDArray[np.intp], cols: NDArray[np.intp]) -> FloatArray:
        """Return the map-frame centres of cells.

        Args:
            rows: (N,) row indices.
            cols: (N,) column indices.

        Returns:
            (N, 2) x, y in the map frame, metres.
        """
        local = np.column_stack([cols + 0.5, rows + 0.5]) * self.resolution_m
        c, s = math.cos(self.origin_yaw_rad), math.sin(self.origin_yaw_rad)
        out: FloatArray = local @ np.array([[c, s], [-s, c]]) + np.asarray(self.origin_xy)
        return out

    def cell_of(self, xy: FloatArray) -> tuple[NDArray[np.intp], NDArray[np.intp], BoolArray]:
        """Return the cell holding each map-frame point.

        Args:
            xy: (N, 2) points in the map frame, metres.

        Returns:
            (rows, cols, inside): indices (clipped into the grid) and whether the point lies
            on the grid at all.
        """
        c, s = math.cos(self.origin_yaw_rad), math.sin(self.origin_yaw_rad)
        local = (np.asarray(xy, dtype=np.float64) - np.asarray(self.origin_xy)) @ np.array(
            [[c, -s], [s, c]]
        )
        cols = np.floor(local[:, 0] / self.resolution_m)
        rows = np.floor(local[:, 1] / self.resolution_m)
        height, width = self.shape
        inside = (cols >= 0) & (cols < width) & (rows >= 0) & (rows < height)
        return (
            np.clip(rows, 0, height - 1).astype(np.intp),
            np.clip(cols, 0, width - 1).astype(np.intp),
            inside,
        )
