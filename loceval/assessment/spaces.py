"""Where in the building: its named spaces (rooms) and the one each stretch lies in.

A site engineer reads "beyond 0.025 m for 4.1 s in 2.14 Office", not "from t = 12.3 s".
The building model names its spaces (an IFC's ``IfcSpace`` Name and LongName, a DXF
plan's room labels); the exporters read those files (the CAD libraries live there) and
hand their footprints here as plain polygons in the evaluation frame (:class:`Space`).
This module is the geometry: :func:`locate_in_spaces` finds the space of each position
(vectorised crossing-number test, a bounding-box filter per space), and
:func:`locate_verdict` puts each stretch in the space that holds most of its poses (the
ground truth's positions: where the device really was);
:meth:`~loceval.evaluation.EvaluationResult.with_building` does it for every estimate.

:class:`Building` is what an evaluation knows of its building model: the file, its spaces
and the rule that found them, and the warnings about how it is placed (an up axis that
contradicts its extents, paths outside it: :func:`check_building_extent`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Final

import numpy as np

from loceval.core.arrays import FloatArray, IntArray

if TYPE_CHECKING:
    from loceval.assessment.verdict import FailingSpan, Verdict

__all__ = [
    "Building",
    "Space",
    "check_building_extent",
    "locate_in_spaces",
    "locate_verdict",
]

Z_MARGIN_M: Final = 0.25
"""A position counts as in a space from this far below its floor to this far above its top."""
_CHUNK: Final = 1 << 21  # points x edges compared at once (16 MB of booleans and floats)
_INSIDE_SHARE: Final = 0.5  # a reading of the model fits when half the paths lie inside it
_TALL_RATIO: Final = 3.0  # "far taller than wide": height over the larger horizontal extent
_BAND_MARGIN_M: Final = 0.5  # the paths may leave the floor-to-ceiling band by this much


@dataclass(frozen=True, slots=True, eq=False)
class Space:
    """One named space of a building: its footprint and the heights it spans.

    Attributes:
        name: what the building calls it (``"2.14 Office"``).
        outline_xy: (K, 2) float64 footprint in the evaluation frame, metres, K >= 3, a
            ring (the first vertex is not repeated).
        floor_m: the height of its floor in the evaluation frame, metres (-inf: any).
        ceiling_m: the height of its top, metres (inf: any).
    """

    name: str
    outline_xy: FloatArray
    floor_m: float = -math.inf
    ceiling_m: float = math.inf

    def __post_init__(self) -> None:
        """Copy the outline read-only and check it.

        Raises:
            ValueError: not (K, 2) finite values with K >= 3 (a bug of the reader).
        """
        outline = np.array(self.outline_xy, dtype=np.float64)
        if outline.ndim != 2 or outline.shape[1] != 2 or outline.shape[0] < 3:
            msg = f"A space's outline needs (K >= 3, 2) points, got {outline.shape!r}."
            raise ValueError(msg)
        if not np.isfinite(outline).all():
            msg = f"The outline of space {self.name!r} has a non-finite point."
            raise ValueError(msg)
        outline.flags.writeable = False
        object.__setattr__(self, "outline_xy", outline)

    @property
    def area_m2(self) -> float:
        """Return the footprint's area, square metres (shoelace formula)."""
        x, y = self.outline_xy[:, 0], self.outline_xy[:, 1]
        return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))

    def to_dict(self) -> dict[str, object]:
        """Return the result document's record: name, area and heights (None: any)."""
        return {
            "name": self.name,
            "area_m2": round(self.area_m2, 3),
            "floor_m": None if math.isinf(self.floor_m) else self.floor_m,
            "ceiling_m": None if math.isinf(self.ceiling_m) else self.ceiling_m,
        }


@dataclass(frozen=True, slots=True, eq=False)
class Building:
    """What an evaluation knows of the building model it was placed on.

    Attributes:
        source: the model's file name.
        spaces: its named spaces, in the evaluation frame.
        spaces_from: how they were found (``"IfcSpace Name and LongName"``), "" without.
        warnings: what is wrong with how it is placed, and what to set.
    """

    source: str
    spaces: tuple[Space, ...] = ()
    spaces_from: str = ""
    warnings: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, object]:
        """Return the result document's ``building`` object."""
        return {
            "source": self.source,
            "spaces_from": self.spaces_from or None,
            "spaces": [s.to_dict() for s in self.spaces],
            "warnings": list(self.warnings),
        }


def locate_in_spaces(
    positions_xyz: FloatArray, spaces: Sequence[Space], *, z_margin_m: float = Z_MARGIN_M
) -> IntArray:
    """Return the space each position lies in: an index into ``spaces``, or -1 for none.

    A position lies in a space when its x-y is inside the footprint (crossing-number test)
    and its height is between the floor and the top, ``z_margin_m`` either side. Where
    spaces overlap (a zone inside a hall), the smallest footprint wins.

    Args:
        positions_xyz: (N, 3) positions in the evaluation frame, metres.
        spaces: the spaces.
        z_margin_m: how far below the floor and above the top still counts, metres.

    Returns:
        (N,) intp indices into ``spaces`` (-1: in none).
    """
    points = np.asarray(positions_xyz, dtype=np.float64).reshape(-1, 3)
    out: IntArray = np.full(len(points), -1, dtype=np.intp)
    if not len(points) or not spaces:
        return out
    # the largest first, so a smaller space inside it overwrites it
    order = sorted(range(len(spaces)), key=lambda k: -spaces[k].area_m2)
    for k in order:  # one iteration per space (tens to hundreds), not per pose
        space = spaces[k]
        lo, hi = space.outline_xy.min(axis=0), space.outline_xy.max(axis=0)
        z = points[:, 2]
        candidates = np.flatnonzero(
            (points[:, 0] >= lo[0])
            & (points[:, 0] <= hi[0])
            & (points[:, 1] >= lo[1])
            & (points[:, 1] <= hi[1])
            & (z >= space.floor_m - z_margin_m)
            & (z <= space.ceiling_m + z_margin_m)
        )
        if len(candidates):
            inside = _inside(points[candidates, :2], space.outline_xy)
            out[candidates[inside]] = k
    return out


def _inside(points_xy: FloatArray, ring: FloatArray) -> np.ndarray:
    """Return (M,) whether each point is inside the ring (crossing number, even-odd rule)."""
    a = ring
    b = np.roll(ring, -1, axis=0)
    x0, y0, x1, y1 = a[:, 0], a[:, 1], b[:, 0], b[:, 1]
    dy = np.where(y1 == y0, 1.0, y1 - y0)  # horizontal edges never cross (masked below)
    step = max(1, _CHUNK // max(len(ring), 1))
    inside = np.zeros(len(points_xy), dtype=bool)
    for start in range(0, len(points_xy), step):  # chunks bound the memory, not per pose
        px = points_xy[start : start + step, 0:1]
        py = points_xy[start : start + step, 1:2]
        straddles = (y0 > py) != (y1 > py)
        crossing_x = x0 + (py - y0) * (x1 - x0) / dy
        crossings = np.count_nonzero(straddles & (px < crossing_x), axis=1)
        inside[start : start + step] = crossings % 2 == 1
    return inside


def locate_verdict(verdict: Verdict, positions_xyz: FloatArray, building: Building) -> Verdict:
    """Return the verdict with each stretch beyond the tolerance in its space.

    Each stretch takes the space that holds most of its poses (the ground truth's
    positions, vectorised over all stretches at once); a stretch none of whose poses lies
    in a named space keeps ``space=None``.

    Args:
        verdict: an estimate's verdict.
        positions_xyz: (N, 3) the ground truth at the estimate's matched poses (the
            stretches' indices count these), evaluation frame, metres.
        building: the building model's spaces, in the evaluation frame.

    Returns:
        A new verdict; ``verdict`` is unchanged.
    """
    spans = verdict.failing_spans
    if not spans or not building.spaces:
        return verdict
    named = _span_spaces(spans, positions_xyz, building.spaces)
    located = tuple(replace(s, space=name) for s, name in zip(spans, named, strict=True))
    return replace(verdict, failing_spans=located)


def _span_spaces(
    spans: Sequence[FailingSpan], positions_xyz: FloatArray, spaces: Sequence[Space]
) -> list[str | None]:
    """Return the name of the space holding most poses of each stretch (None: none)."""
    first = np.array([s.first_index for s in spans], dtype=np.intp)
    sizes = np.array([s.last_index - s.first_index + 1 for s in spans], dtype=np.intp)
    # every pose of every stretch at once: its stretch and its pose index
    which = np.repeat(np.arange(len(spans)), sizes)
    offsets = np.cumsum(sizes) - sizes
    index = np.arange(int(sizes.sum())) - np.repeat(offsets, sizes) + np.repeat(first, sizes)
    where = locate_in_spaces(positions_xyz[index], spaces)
    columns = len(spaces) + 1  # column 0: in no space
    counts = np.bincount(which * columns + where + 1, minlength=len(spans) * columns)
    counts = counts.reshape(len(spans), columns)[:, 1:]
    best = np.argmax(counts, axis=1)  # ties: the first space
    has = counts[np.arange(len(spans)), best] > 0
    return [spaces[int(b)].name if h else None for b, h in zip(best, has, strict=True)]


def check_building_extent(
    bounds_by_up: Mapping[str, FloatArray],
    chosen: str,
    positions_xyz: FloatArray,
    *,
    source: str,
    option: str = "building_up",
) -> tuple[str, ...]:
    """Return warnings when a building's extents contradict its up axis or the paths.

    A reading of the model (its up axis) fits when at least half the ground truth's
    positions lie inside its bounding box, within 0.5 m of its floor-to-ceiling band. The
    chosen reading is questioned when it does not fit, or when the model stands far taller
    than it is wide (three times its larger horizontal extent) while another reading lies
    flat and fits as well; the warning names the reading that fits, as the value to set.
    When no reading fits, the paths are outside the model (the site transform, the
    model's units or its coordinates are off).

    Args:
        bounds_by_up: each reading's (2, 3) bounding box [min, max] of the model in model
            coordinates, metres, Z up, by its up axis value (``"z"``, ``"y"``); only the
            chosen one for a model whose up axis is fixed (IFC).
        chosen: the reading used.
        positions_xyz: (N, 3) the ground truth in model coordinates (site applied), metres.
        source: the model's file name, for the message.
        option: how the user names the up-axis option.

    Returns:
        Zero or one warning.
    """
    points = np.asarray(positions_xyz, dtype=np.float64).reshape(-1, 3)
    if not len(points) or chosen not in bounds_by_up:
        return ()
    fits = {up: _inside_share(np.asarray(b), points) for up, b in bounds_by_up.items()}
    tall = {up: _is_tall(np.asarray(b)) for up, b in bounds_by_up.items()}
    lo, hi = np.asarray(bounds_by_up[chosen])
    size = hi - lo
    others = [u for u in bounds_by_up if u != chosen and fits[u] >= _INSIDE_SHARE]
    better = max(others, key=lambda u: (fits[u], not tall[u]), default=None)
    shape = f"{size[0]:.1f} x {size[1]:.1f} m and {size[2]:.1f} m tall"
    inside = f"{fits[chosen] * 100:.0f} % of the ground truth lies inside it"
    if fits[chosen] < _INSIDE_SHARE:
        if better is not None:
            return (
                (
                    f"The building model {source!r} read with {option}={chosen} is {shape}, and "
                    f"only {inside}; read with {option}={better}, {fits[better] * 100:.0f} % does: "
                    f"set {option} to {better}."
                ),
            )
        return (
            (
                f"The paths lie outside the building model {source!r} ({shape}; {inside}); "
                "check the site transform (site or site_matrix), the model's units and its up "
                "axis."
            ),
        )
    if tall[chosen] and better is not None and not tall[better]:
        return (
            (
                f"The building model {source!r} read with {option}={chosen} is {shape}: far "
                f"taller than wide, as a model lying on its side; read with {option}={better} "
                f"it lies flat and {fits[better] * 100:.0f} % of the ground truth is inside it: "
                f"set {option} to {better}."
            ),
        )
    return ()


def _inside_share(bounds: FloatArray, points: FloatArray) -> float:
    """Return the share of points inside the box, within the band margin in height."""
    lo, hi = bounds
    xy = np.all((points[:, :2] >= lo[:2]) & (points[:, :2] <= hi[:2]), axis=1)
    z = (points[:, 2] >= lo[2] - _BAND_MARGIN_M) & (points[:, 2] <= hi[2] + _BAND_MARGIN_M)
    return float(np.mean(xy & z))


def _is_tall(bounds: FloatArray) -> bool:
    """Whether a box stands far taller than its larger horizontal extent."""
    size = bounds[1] - bounds[0]
    return bool(size[2] > _TALL_RATIO * max(float(size[0]), float(size[1]), 1e-9))
