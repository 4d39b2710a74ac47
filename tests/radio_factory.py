"""Synthetic radio recordings: a walk through rooms, fixed anchors and their range measurements.

The floor: a corridor ``x ∈ [0, 30], y ∈ [0, 2]`` with three rooms north of it
(``[0, 10] / [10, 20] / [20, 30] × [2, 8]``). The walk goes along the corridor and into
each room at 1 m/s; twelve anchors hang at different heights in the corridor and rooms,
and a thirteenth (``FAR``) is beyond radio range, so it is never heard.

Ranges are generated from the exact piecewise-linear walk (not from the sampled
reference), so the ranging evaluation's interpolation is part of what the tests check.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from loceval.core.arrays import BoolArray, FloatArray
from loceval.readers.radio import Anchors, Ranges
from loceval.trajectory import Trajectory

T0_NS = 1_700_000_000 * 10**9
"""A plausible epoch start (2023-11-14) for synthetic stamps."""

WAYPOINTS_XY = np.array(
    [
        [1.0, 1.0], [5.0, 1.0], [5.0, 5.0], [8.0, 6.5], [3.0, 6.0], [5.0, 1.0],
        [15.0, 1.0], [15.0, 5.0], [12.0, 6.5], [18.0, 6.0], [15.0, 1.0],
        [25.0, 1.0], [25.0, 6.0], [28.0, 4.0], [22.0, 3.0], [25.0, 1.0], [29.0, 1.0],
    ]
)  # fmt: skip
"""The walk: corridor, room 1, corridor, room 2, corridor, room 3, corridor end."""

ANCHOR_IDS = (*(f"A{k:02d}" for k in range(1, 13)), "FAR")
ANCHOR_XYZ = np.array(
    [
        [0.2, 0.2, 2.6], [9.8, 1.8, 0.4], [0.3, 7.7, 2.8], [9.6, 7.8, 0.5],
        [14.0, 0.1, 2.7], [19.8, 1.9, 0.3], [10.3, 7.9, 2.4], [19.7, 7.6, 0.6],
        [24.0, 0.2, 2.9], [29.8, 1.8, 0.5], [20.4, 7.8, 2.5], [29.7, 7.7, 1.0],
        [80.0, 40.0, 2.5],
    ]
)  # fmt: skip
"""Anchor positions, metres: heights alternate so that 3D positioning is determined."""

SPEED_M_S = 1.0
TAG_HEIGHT_M = 1.2


def walk_position(t_s: FloatArray) -> FloatArray:
    """Return the (N, 3) exact positions of the walk at ``t_s`` seconds after its start."""
    seg = np.linalg.norm(np.diff(WAYPOINTS_XY, axis=0), axis=1)
    cum = np.concatenate(([0.0], np.cumsum(seg))) / SPEED_M_S
    x = np.interp(t_s, cum, WAYPOINTS_XY[:, 0])
    y = np.interp(t_s, cum, WAYPOINTS_XY[:, 1])
    return np.column_stack((x, y, np.full(np.shape(t_s), TAG_HEIGHT_M)))


def walk_duration_s() -> float:
    """Return how long the walk takes, seconds."""
    return float(np.linalg.norm(np.diff(WAYPOINTS_XY, axis=0), axis=1).sum() / SPEED_M_S)


def walk_yaw(t_s: FloatArray) -> FloatArray:
    """Return the heading (rad) of the segment the walk is on at ``t_s``."""
    seg_xy = np.diff(WAYPOINTS_XY, axis=0)
    cum = np.concatenate(([0.0], np.cumsum(np.linalg.norm(seg_xy, axis=1)))) / SPEED_M_S
    k = np.clip(np.searchsorted(cum, t_s, side="right") - 1, 0, len(seg_xy) - 1)
    return np.arctan2(seg_xy[k, 1], seg_xy[k, 0])


def make_reference(
    *,
    rate_hz: float = 100.0,
    t0_ns: int = T0_NS,
    start_s: float = 0.0,
    loss_s: tuple[float, float] | None = None,
    orientation: bool = True,
) -> Trajectory:
    """Return the walk sampled at ``rate_hz`` (yaw along the path), optionally with a loss.

    Args:
        rate_hz: the reference's rate.
        t0_ns: the stamp of the walk's start.
        start_s: drop the poses before this (the reference starts late).
        loss_s: drop the poses strictly inside this interval (tracking loss).
        orientation: whether to include orientations.
    """
    n = int(walk_duration_s() * rate_hz) + 1
    t = np.arange(n) / rate_hz
    keep = t >= start_s
    if loss_s is not None:
        keep &= ~((t > loss_s[0]) & (t < loss_s[1]))
    t = t[keep]
    quat = Rotation.from_euler("z", walk_yaw(t)[:, None]).as_quat() if orientation else None
    stamps = t0_ns + np.rint(t * 1e9).astype(np.int64)
    return Trajectory(stamps, walk_position(t), quat, name="reference", frame_id="building")


def make_anchors() -> Anchors:
    """Return the thirteen anchors (``FAR`` is out of range)."""
    return Anchors(ANCHOR_IDS, ANCHOR_XYZ, source="anchors.csv")


@dataclass(frozen=True, slots=True, eq=False)
class RadioRecording:
    """Generated ranges with the values they were generated from.

    Attributes:
        ranges: the measurements (sorted by time).
        true_m: (N,) the exact distance of each measurement.
        nlos: (N,) whether a non-line-of-sight error was added.
        bias_m: (K,) generated bias per anchor.
        noise_m: (K,) generated noise standard deviation per anchor.
        scale: (K,) generated scale factor per anchor.
    """

    ranges: Ranges
    true_m: FloatArray
    nlos: BoolArray
    bias_m: FloatArray
    noise_m: FloatArray
    scale: FloatArray


def make_ranges(
    rng: np.random.Generator,
    *,
    rate_hz: float = 10.0,
    t0_ns: int = T0_NS,
    bias_m: Sequence[float] | None = None,
    noise_m: Sequence[float] | None = None,
    scale: Sequence[float] | None = None,
    nlos_share: float = 0.0,
    nlos_m: tuple[float, float] = (3.0, 8.0),
    max_range_m: float = 15.0,
    synchronous: bool = False,
    tag_offset_xyz: tuple[float, float, float] | None = None,
    end_s: float | None = None,
) -> RadioRecording:
    """Return ranges from the walk to every anchor within ``max_range_m``.

    Every anchor is ranged at ``rate_hz``; anchor ``j`` (0-based) is ranged ``j * 5 ms``
    after the tick (all at the tick when ``synchronous``). The range is
    ``scale_j * true + bias_j + N(0, noise_j²)`` plus, with probability ``nlos_share``,
    a uniform non-line-of-sight error in ``nlos_m``; it is clipped at 0.

    Args:
        rng: the seeded generator.
        rate_hz: ranging rate per anchor.
        t0_ns: the stamp of the walk's start.
        bias_m: per-anchor bias (default: uniform in [-0.2, 0.3]).
        noise_m: per-anchor noise std (default: uniform in [0.05, 0.2]).
        scale: per-anchor scale factor (default: 1).
        nlos_share: probability of a non-line-of-sight error.
        nlos_m: range of the non-line-of-sight error, metres.
        max_range_m: anchors farther than this are not heard.
        synchronous: range every anchor at the tick itself.
        tag_offset_xyz: the tag in the walker's body frame (yaw along the path).
        end_s: last tick, seconds (default: the walk's end).
    """
    k = len(ANCHOR_IDS)
    bias = rng.uniform(-0.2, 0.3, k) if bias_m is None else np.asarray(bias_m, dtype=float)
    noise = rng.uniform(0.05, 0.2, k) if noise_m is None else np.asarray(noise_m, dtype=float)
    factor = np.ones(k) if scale is None else np.asarray(scale, dtype=float)
    last = walk_duration_s() if end_s is None else end_s
    ticks = np.arange(0.0, last - 0.1, 1.0 / rate_hz)
    lag = np.zeros(k) if synchronous else np.arange(k) * 0.005
    t = (ticks[:, None] + lag[None, :]).ravel()
    anchor = np.tile(np.arange(k), ticks.size)
    tag = walk_position(t)
    if tag_offset_xyz is not None:
        tag = tag + Rotation.from_euler("z", walk_yaw(t)[:, None]).apply(np.asarray(tag_offset_xyz))
    true = np.linalg.norm(tag - ANCHOR_XYZ[anchor], axis=1)
    heard = true <= max_range_m
    t, anchor, true = t[heard], anchor[heard], true[heard]
    measured = factor[anchor] * true + bias[anchor] + rng.normal(0.0, 1.0, t.size) * noise[anchor]
    nlos = rng.uniform(size=t.size) < nlos_share
    measured = measured + nlos * rng.uniform(nlos_m[0], nlos_m[1], t.size)
    measured = np.maximum(measured, 0.0)
    stamps = t0_ns + np.rint(t * 1e9).astype(np.int64)
    order = np.argsort(stamps, kind="stable")
    ranges = Ranges(
        anchors=make_anchors(),
        stamps_ns=stamps[order],
        anchor_index=anchor[order],
        range_m=measured[order],
        source="ranges.csv",
    )
    return RadioRecording(ranges, true[order], nlos[order], bias, noise, factor)


def write_anchors_csv(path: Path, anchors: Anchors) -> Path:
    """Write ``id,x,y,z`` rows with shortest round-trip floats."""
    rows = ["id,x,y,z"]
    rows += [
        f"{i},{p[0]!r},{p[1]!r},{p[2]!r}"
        for i, p in zip(anchors.ids, anchors.positions_xyz.tolist(), strict=True)
    ]
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def write_ranges_csv(path: Path, ranges: Ranges, *, rssi: bool = False) -> Path:
    """Write ``t,anchor_id,range_m[,rssi]`` rows, ``t`` in seconds with nanosecond digits."""
    header = "t,anchor_id,range_m" + (",rssi" if rssi else "")
    rows = [header]
    for k in range(len(ranges)):
        ns = int(ranges.stamps_ns[k])
        cells = [
            f"{ns // 10**9}.{ns % 10**9:09d}",
            ranges.anchors.ids[int(ranges.anchor_index[k])],
            repr(float(ranges.range_m[k])),
        ]
        if rssi:
            cells.append(f"{-60.0 - float(ranges.range_m[k]):.1f}")
        rows.append(",".join(cells))
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path
