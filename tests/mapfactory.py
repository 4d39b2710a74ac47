"""Generated floor plans and occupancy maps made from them with a known distortion.

A plan is a set of wall segments; a map is the plan's walls drawn into a grid after a known
plan -> map transform (scale, rotation, translation), optionally bent (every point beyond
``bend_x_m`` turned by ``bend_deg`` about the bend line's point), with Gaussian noise on
the wall points and square clutter blobs inside the rooms. Cells inside the building's
outline that no wall touches are free, the rest unknown, as a SLAM map of a fully driven
floor. Everything is vectorised, so the same factory makes the benchmark's 4000 x 4000 map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from loceval.maps.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid


def office_plan(width_m: float = 20.0, depth_m: float = 12.0, rooms: int = 4) -> np.ndarray:
    """A rectangle outline, a corridor wall along x and ``rooms`` rooms on one side.

    Returns:
        (K, 2, 2) segments, metres.
    """
    w, d = width_m, depth_m
    corridor = 0.4 * d
    segments = [
        [[0, 0], [w, 0]],
        [[w, 0], [w, d]],
        [[w, d], [0, d]],
        [[0, d], [0, 0]],
        [[0, corridor], [w, corridor]],
    ]
    for k in range(1, rooms):
        x = w * k / rooms
        segments.append([[x, corridor], [x, d]])
    return np.asarray(segments, dtype=np.float64)


def grid_plan(cells_x: int, cells_y: int, room_m: float) -> np.ndarray:
    """A building of ``cells_x`` by ``cells_y`` square rooms: many short wall segments."""
    xs = np.arange(cells_x + 1) * room_m
    ys = np.arange(cells_y + 1) * room_m
    # each wall is cut into room-long pieces (as CAD exports them)
    hx0, hy = np.meshgrid(xs[:-1], ys)
    horizontal = np.stack(
        [
            np.column_stack([hx0.ravel(), hy.ravel()]),
            np.column_stack([hx0.ravel() + room_m, hy.ravel()]),
        ],
        axis=1,
    )
    vx, vy0 = np.meshgrid(xs, ys[:-1])
    vertical = np.stack(
        [
            np.column_stack([vx.ravel(), vy0.ravel()]),
            np.column_stack([vx.ravel(), vy0.ravel() + room_m]),
        ],
        axis=1,
    )
    return np.concatenate([horizontal, vertical])


@dataclass(frozen=True)
class Distortion:
    """The plan -> map transform of a generated map: map = s R(yaw) plan + t, then bent."""

    scale: float = 1.0
    yaw_deg: float = 0.0
    translation: tuple[float, float] = (0.0, 0.0)
    bend_x_m: float | None = None
    bend_deg: float = 0.0

    def bent(self, xy: np.ndarray) -> np.ndarray:
        """Bend plan points: beyond ``bend_x_m`` turned by ``bend_deg`` about (bend_x_m, y0)."""
        if self.bend_x_m is None:
            return xy
        out = xy.copy()
        beyond = xy[:, 0] > self.bend_x_m
        a = math.radians(self.bend_deg)
        rel = xy[beyond] - [self.bend_x_m, 0.0]
        out[beyond] = rel @ np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]]) + [
            self.bend_x_m,
            0.0,
        ]
        return out

    def unbent(self, xy: np.ndarray) -> np.ndarray:
        """Undo :meth:`bent` (for points of the plane, not only of walls)."""
        if self.bend_x_m is None:
            return xy
        a = -math.radians(self.bend_deg)
        rel = xy - [self.bend_x_m, 0.0]
        back = rel @ np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
        out = xy.copy()
        beyond = back[:, 0] > 0.0
        out[beyond] = back[beyond] + [self.bend_x_m, 0.0]
        return out

    def apply(self, xy: np.ndarray) -> np.ndarray:
        """Plan points -> map points."""
        a = math.radians(self.yaw_deg)
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        return self.scale * self.bent(xy) @ rot.T + np.asarray(self.translation)

    def unapply(self, xy: np.ndarray) -> np.ndarray:
        """Map points -> plan points."""
        a = math.radians(self.yaw_deg)
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        return self.unbent(((xy - np.asarray(self.translation)) / self.scale) @ rot)


def draw_map(
    plan: np.ndarray,
    distortion: Distortion,
    *,
    resolution_m: float,
    rng: np.random.Generator,
    noise_m: float = 0.0,
    clutter_xy: np.ndarray | None = None,
    clutter_size_m: float = 0.4,
    margin_m: float = 1.013,
) -> OccupancyGrid:
    """Draw the plan's walls, distorted, into an occupancy grid (origin at the lower left).

    The margin is no multiple of the resolution, so axis-parallel walls do not run along
    cell borders (where a wall's cells would all lie half a cell off).
    """
    a, b = plan[:, 0], plan[:, 1]
    lengths = np.linalg.norm(b - a, axis=1)
    counts = np.ceil(lengths / (resolution_m / 4)).astype(int) + 1
    owner = np.repeat(np.arange(len(plan)), counts)
    first = np.cumsum(counts) - counts
    t = (np.arange(owner.size) - np.repeat(first, counts)) / np.repeat(counts - 1, counts)
    wall_plan = a[owner] + t[:, None] * (b - a)[owner]
    wall_map = distortion.apply(wall_plan) + rng.normal(0.0, noise_m, wall_plan.shape)
    corners = distortion.apply(plan.reshape(-1, 2))
    low = corners.min(axis=0) - margin_m
    high = corners.max(axis=0) + margin_m
    width, height = np.ceil((high - low) / resolution_m).astype(int)
    states = np.full((height, width), UNKNOWN, dtype=np.int8)
    rows, cols = np.mgrid[0:height, 0:width]
    centres = np.column_stack([cols.ravel() + 0.5, rows.ravel() + 0.5]) * resolution_m + low
    in_plan = distortion.unapply(centres)
    plan_low, plan_high = plan.reshape(-1, 2).min(axis=0), plan.reshape(-1, 2).max(axis=0)
    inside = ((in_plan > plan_low) & (in_plan < plan_high)).all(axis=1)
    states.ravel()[inside] = FREE
    ij = np.floor((wall_map - low) / resolution_m).astype(int)
    states[ij[:, 1], ij[:, 0]] = OCCUPIED
    if clutter_xy is not None:
        for x, y in distortion.apply(np.asarray(clutter_xy, dtype=float)):  # a few blobs
            box = (np.abs(centres - [x, y]) <= clutter_size_m / 2).all(axis=1)
            states.ravel()[box] = OCCUPIED
    return OccupancyGrid(states, resolution_m, (float(low[0]), float(low[1])), 0.0, source="gen")


def write_map_server(
    folder: Path, grid: OccupancyGrid, *, name: str = "map", suffix: str = ".pgm"
) -> Path:
    """Write map_server's YAML and its PGM (or PNG) for a grid; return the YAML's path."""
    image = np.full(grid.states.shape, 205, dtype=np.uint8)
    image[grid.states == FREE] = 254
    image[grid.states == OCCUPIED] = 0
    image = image[::-1]
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}{suffix}"
    if suffix == ".pgm":
        height, width = image.shape
        path.write_bytes(f"P5\n# CREATOR: test\n{width} {height}\n255\n".encode() + image.tobytes())
    else:
        from PIL import Image

        Image.fromarray(image).save(path)
    x, y = grid.origin_xy
    yaml = folder / f"{name}.yaml"
    yaml.write_text(
        f"image: {path.name}\nresolution: {grid.resolution_m}\norigin: [{x}, {y}, "
        f"{grid.origin_yaw_rad}]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
        encoding="utf-8",
    )
    return yaml


def _message(types: object, grid: OccupancyGrid, stamp_s: int) -> object:
    """A nav_msgs/msg/OccupancyGrid of a grid (ROS values: -1, 0, 100)."""
    t = types  # the typestore's types
    values = np.full(grid.states.shape, -1, dtype=np.int8)
    values[grid.states == FREE] = 0
    values[grid.states == OCCUPIED] = 100
    yaw = grid.origin_yaw_rad
    pose = t["geometry_msgs/msg/Pose"](  # type: ignore[index]
        position=t["geometry_msgs/msg/Point"](x=grid.origin_xy[0], y=grid.origin_xy[1], z=0.0),  # type: ignore[index]
        orientation=t["geometry_msgs/msg/Quaternion"](  # type: ignore[index]
            x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
        ),
    )
    stamp = t["builtin_interfaces/msg/Time"](sec=stamp_s, nanosec=0)  # type: ignore[index]
    info = t["nav_msgs/msg/MapMetaData"](  # type: ignore[index]
        map_load_time=stamp,
        resolution=grid.resolution_m,
        width=grid.shape[1],
        height=grid.shape[0],
        origin=pose,
    )
    header = t["std_msgs/msg/Header"](stamp=stamp, frame_id="map")  # type: ignore[index]
    return t["nav_msgs/msg/OccupancyGrid"](header=header, info=info, data=values.ravel())  # type: ignore[index]


def write_map_bag(folder: Path, grids: list[tuple[int, OccupancyGrid]]) -> Path:
    """Write a ROS 2 bag ``folder/run`` whose ``/map`` topic holds the grids at their seconds."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    bag = folder / "run"
    with Writer(bag, version=9) as writer:
        conn = writer.add_connection("/map", "nav_msgs/msg/OccupancyGrid", typestore=store)
        for stamp_s, grid in grids:  # a handful of maps
            raw = store.serialize_cdr(_message(store.types, grid, stamp_s), conn.msgtype)
            writer.write(conn, stamp_s * 1_000_000_000, raw)
    return bag
