"""An estimate's path cut where its ATE changes colour bin: the runs every CAD file draws.

A noisy estimate changes bin every few poses, so a 50,000-pose path is 25,000 runs. They
are cut, simplified and gathered with NumPy into one :class:`ATERunArrays` per path (what
the writers of many runs take: the .3dm records, the JSON, the IFC and DXF text); the
per-run :class:`ATERun` views are made from it for the writers that draw run by run.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from loceval.core.arrays import BoolArray, FloatArray, IntArray
from loceval.core.polyline import simplify_rdp_runs

__all__ = ["ATERun", "ATERunArrays", "cut_ate_runs", "no_ate_runs"]


@dataclass(frozen=True, slots=True, eq=False)
class ATERun:
    """A stretch of an estimate's path whose ATE stays in one bin.

    Attributes:
        path: name of the estimate's path.
        piece: which continuous piece of the path it lies on.
        bin_index: index into the placement's :meth:`Placement.ate_bins`.
        vertices: (K, 3) model coordinates in the output units (K >= 2; consecutive runs
            of one piece share their joining vertex).
        local_vertices: (K, 3) ``vertices`` minus the placement's base point.
    """

    path: str
    piece: int
    bin_index: int
    vertices: FloatArray
    local_vertices: FloatArray


@dataclass(frozen=True, slots=True, eq=False)
class ATERunArrays:
    """The R ATE runs of an estimate's path as flat arrays, run after run.

    Attributes:
        path: name of the estimate's path.
        piece: (R,) the continuous piece each run lies on.
        bin_index: (R,) each run's index into the placement's ATE bins.
        offsets: (R + 1,) run ``r`` goes through ``vertices[offsets[r]:offsets[r + 1]]``.
        vertices: (V, 3) model coordinates in the output units (a run's joining vertex is
            in both runs).
        local_vertices: (V, 3) ``vertices`` minus the placement's base point.
    """

    path: str
    piece: IntArray
    bin_index: IntArray
    offsets: IntArray
    vertices: FloatArray
    local_vertices: FloatArray

    def __len__(self) -> int:
        """Return the number of runs."""
        return len(self.bin_index)

    def first_of_each_bin(self) -> IntArray:
        """Return the index of the first run of each bin present, in run order."""
        _, first = np.unique(self.bin_index, return_index=True)
        out: IntArray = np.sort(first).astype(np.intp)
        return out

    def runs(self) -> list[ATERun]:
        """Return each run as an :class:`ATERun` (views into these arrays)."""
        vertices, local = self.vertices, self.local_vertices
        return [
            ATERun(self.path, k, b, vertices[start:stop], local[start:stop])
            for k, b, start, stop in zip(
                self.piece.tolist(),
                self.bin_index.tolist(),
                self.offsets[:-1].tolist(),
                self.offsets[1:].tolist(),
                strict=True,
            )
        ]


def cut_ate_runs(
    name: str,
    model: FloatArray,
    which: IntArray,
    jump: BoolArray,
    *,
    tolerance: float,
    base_point: FloatArray,
) -> ATERunArrays:
    """Cut a path where its ATE bin changes or it breaks; simplify each run on its own.

    Args:
        name: the path's name.
        model: (N, 3) the estimate's poses in model coordinates, output units.
        which: (N,) the ATE bin of each pose.
        jump: (N - 1,) True after each pose that ends a continuous piece.
        tolerance: the simplification tolerance, output units.
        base_point: (3,) what local vertices are relative to, output units.

    Returns:
        The runs of two vertices or more; runs never cross a break, within one piece they
        join.
    """
    piece = np.concatenate(([0], np.cumsum(jump)))
    change = (np.diff(which) != 0) | jump
    starts = np.concatenate(([0], np.flatnonzero(change) + 1))
    ends = np.concatenate((starts[1:], [len(which)]))
    # a run continues to the next run's first vertex unless a break lies between
    ends = np.where((ends < len(which)) & ~np.append(jump, True)[ends - 1], ends + 1, ends)
    drawn = ends - starts >= 2
    starts, ends = starts[drawn], ends[drawn]
    if not len(starts):
        return no_ate_runs(name)
    # every run simplified in one work list (thousands of short runs on a noisy path)
    keep, _ = simplify_rdp_runs(model, starts, ends, tolerance)
    # every run's kept vertices gathered at once (runs share their joining vertex)
    kept = np.flatnonzero(keep)
    first, last = np.searchsorted(kept, starts), np.searchsorted(kept, ends)
    sizes = last - first
    offsets = np.concatenate(([0], np.cumsum(sizes))).astype(np.intp)
    gather = kept[np.arange(offsets[-1]) - np.repeat(offsets[:-1] - first, sizes)]
    vertices = model[gather]
    return ATERunArrays(
        path=name,
        piece=piece[starts].astype(np.intp),
        bin_index=which[starts].astype(np.intp),
        offsets=offsets,
        vertices=vertices,
        local_vertices=vertices - base_point,
    )


def no_ate_runs(name: str) -> ATERunArrays:
    """Return the runs of a path without any (the reference, or an estimate too short)."""
    empty = np.zeros((0, 3))
    none = np.zeros(0, dtype=np.intp)
    return ATERunArrays(name, none, none, np.zeros(1, dtype=np.intp), empty, empty.copy())
