"""The display set of a long path: few enough vertices to stay interactive, every peak kept.

A browser draws 40,000 line vertices at once without effort; a 1,000,000-pose reference
is too many to send, parse and pick from. :func:`display_indices` keeps, vectorised:

- every pose of a path short enough (``budget`` or fewer poses): nothing is dropped;
- otherwise the path is cut into equal buckets of consecutive poses and each bucket keeps
  its first and last pose, the poses of least and greatest x, y and z (the M4 rule of
  line-chart decimation, in three coordinates: the drawn outline keeps every corner and
  excursion a pixel could show) and, for an estimate, the poses of least and greatest ATE
  (so every error peak is drawn and labelled at its true size);
- always both ends of every break (tracking loss), so a break stays a break, and the
  poses named in ``must_keep`` (the ranked greatest errors).

The full data stay one click away in ``errors.csv``.
"""

from __future__ import annotations

from typing import Final

import numpy as np

from loceval.core.arrays import BoolArray, FloatArray, IntArray

__all__ = ["DISPLAY_BUDGET", "display_indices"]

DISPLAY_BUDGET: Final = 20_000
"""Most poses of one path drawn as they are; a longer path is reduced to about this many."""
_KEPT_PER_BUCKET: Final = 10  # first, last, min/max of x, y, z and of the error


def display_indices(
    positions_xyz: FloatArray,
    breaks: BoolArray,
    *,
    errors_m: FloatArray | None = None,
    must_keep: IntArray | None = None,
    budget: int = DISPLAY_BUDGET,
) -> IntArray:
    """Return the increasing indices of the poses a viewer draws.

    Args:
        positions_xyz: (N, 3) positions of the path.
        breaks: (N - 1,) True after each pose that ends a continuous piece.
        errors_m: (N,) ATE per pose, for an estimate (its peaks are kept).
        must_keep: indices that are always kept (the greatest errors).
        budget: paths of at most this many poses are kept whole.

    Returns:
        (M,) increasing indices into ``positions_xyz``.
    """
    n = int(positions_xyz.shape[0])
    if n <= budget:
        return np.arange(n, dtype=np.intp)
    size = max(2, -(-n * _KEPT_PER_BUCKET // budget))  # ceil: buckets of ``size`` poses
    buckets = -(-n // size)
    pad = buckets * size - n
    columns = [positions_xyz[:, k] for k in range(3)]
    if errors_m is not None:
        columns.append(np.asarray(errors_m, dtype=np.float64))
    starts = np.arange(buckets, dtype=np.intp) * size
    kept = [starts, np.minimum(starts + size - 1, n - 1)]
    for column in columns:
        low = np.pad(column, (0, pad), constant_values=np.inf).reshape(buckets, size)
        high = np.pad(column, (0, pad), constant_values=-np.inf).reshape(buckets, size)
        kept.append(starts + np.argmin(low, axis=1))
        kept.append(starts + np.argmax(high, axis=1))
    ends = np.flatnonzero(breaks)
    kept += [ends, ends + 1]
    if must_keep is not None:
        kept.append(np.asarray(must_keep, dtype=np.intp))
    out: IntArray = np.unique(np.concatenate(kept)).astype(np.intp)
    return out[(out >= 0) & (out < n)]
