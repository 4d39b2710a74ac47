"""Surveyed control points and the visits of a device to them.

Control points are a reference that is not a trajectory: a few positions in the building's
frame (a total station's survey, the building's grid marks), position-only, each with the
survey's own uncertainty. A *visit* is a time window in which the device stood on one of
them (the reference-robot paper's floor-grid test, ``001_...`` §IV: the robot's position
saved at each of 45 marks, 135 measurements).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

from loceval.core.arrays import FloatArray, StampsNs
from loceval.errors import InputError

__all__ = ["MIN_CONTROL_POINTS", "ControlPoints", "Visits"]

MIN_CONTROL_POINTS = 3
"""Fewer points cannot fix an alignment or say much about a system."""


def _readonly(array: FloatArray) -> FloatArray:
    out = np.array(array, dtype=np.float64)
    out.flags.writeable = False
    return out


@dataclass(frozen=True, slots=True, eq=False)
class ControlPoints:
    """Surveyed points in the building frame.

    Attributes:
        ids: (N,) point ids as written in the survey, unique.
        positions_xyz: (N, 3) metres, building frame.
        sigma_xyz: (N, 3) the survey's 1-sigma per axis, metres; None when not given.
        source: where the points came from (file name).
        warnings: what the reader noticed.
    """

    ids: tuple[str, ...]
    positions_xyz: FloatArray
    sigma_xyz: FloatArray | None = None
    source: str = ""
    warnings: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        """Copy the arrays read-only and check them."""
        positions = _readonly(self.positions_xyz)
        n = len(self.ids)
        if positions.shape != (n, 3):
            msg = f"Control points need (N, 3) positions for {n} ids, got {positions.shape!r}."
            raise InputError(msg)
        if n < MIN_CONTROL_POINTS:
            msg = (
                f"{n} control points given; at least {MIN_CONTROL_POINTS} are needed to "
                "evaluate against them (add points to the survey file)."
            )
            raise InputError(msg)
        repeated = [pid for pid, count in Counter(self.ids).items() if count > 1]
        if repeated:
            msg = (
                f"Control point id {repeated[0]!r} appears more than once; give every point "
                "its own id."
            )
            raise InputError(msg)
        if not np.isfinite(positions).all():
            msg = "Control point coordinates must be finite numbers; found NaN or inf."
            raise InputError(msg)
        object.__setattr__(self, "positions_xyz", positions)
        if self.sigma_xyz is not None:
            sigma = _readonly(self.sigma_xyz)
            if sigma.shape != (n, 3) or not (np.isfinite(sigma).all() and (sigma >= 0).all()):
                msg = "Control point sigmas must be finite, non-negative metres per axis."
                raise InputError(msg)
            object.__setattr__(self, "sigma_xyz", sigma)

    def __len__(self) -> int:
        """Return the number of points."""
        return len(self.ids)

    def index_of(self, ids: list[str], *, where: str) -> np.ndarray:
        """Return the indices of ``ids``.

        Raises:
            InputError: an id is not a control point (the message names it and ``where``).
        """
        lookup = {pid: k for k, pid in enumerate(self.ids)}
        unknown = [pid for pid in ids if pid not in lookup]
        if unknown:
            shown = ", ".join(repr(u) for u in sorted(set(unknown))[:5])
            known = ", ".join(self.ids[:8]) + (" ..." if len(self.ids) > 8 else "")
            msg = (
                f"{where} names control points that are not in the survey: {shown}; known: {known}."
            )
            raise InputError(msg)
        return np.array([lookup[pid] for pid in ids], dtype=np.int64)

    def min_spacing_m(self) -> float:
        """Return the smallest distance between two points, metres."""
        diff = self.positions_xyz[:, None, :] - self.positions_xyz[None, :, :]
        dist = np.sqrt((diff**2).sum(axis=2))
        dist[np.diag_indices(len(self))] = np.inf
        return float(dist.min())


@dataclass(frozen=True, slots=True, eq=False)
class Visits:
    """When the device stood on which control point.

    Attributes:
        point_index: (V,) index into the control points of each visit.
        start_ns: (V,) first stamp of each visit (the estimate's clock).
        end_ns: (V,) last stamp of each visit, inclusive.
        source: ``"file"``, ``"auto"`` or the topic the arrivals came from.
    """

    point_index: np.ndarray
    start_ns: StampsNs
    end_ns: StampsNs
    source: str = "file"

    def __post_init__(self) -> None:
        """Copy the arrays read-only and check them."""
        index = np.array(self.point_index, dtype=np.int64)
        start = np.array(self.start_ns, dtype=np.int64)
        end = np.array(self.end_ns, dtype=np.int64)
        if not (index.shape == start.shape == end.shape) or index.ndim != 1:
            msg = "Visits need one point, one start and one end each."
            raise InputError(msg)
        if (end < start).any():
            k = int(np.flatnonzero(end < start)[0])
            msg = f"Visit {k + 1} ends before it starts; give t_start <= t_end in seconds."
            raise InputError(msg)
        order = np.argsort(start, kind="stable")
        for name, array in (("point_index", index), ("start_ns", start), ("end_ns", end)):
            sorted_array = array[order]
            sorted_array.flags.writeable = False
            object.__setattr__(self, name, sorted_array)

    def __len__(self) -> int:
        """Return the number of visits."""
        return int(self.point_index.shape[0])
