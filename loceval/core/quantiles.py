"""Medians and linear quantiles, bit for bit NumPy's, without loading ``numpy.ma``.

NumPy imports ``numpy.ma`` the first time ``np.median`` or ``np.quantile`` runs (to look
for masked NaNs), about 10 ms of every command-line evaluation. These functions do what
NumPy does for a plain 1-D array: the same partition (same ``kth`` list), the same mean of
the middle values, the same linear interpolation (Hyndman & Fan's method 7); NaN in the
input gives NaN, as there.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from loceval.core.arrays import FloatArray

__all__ = ["median", "quantiles"]


def median(values: ArrayLike) -> float:
    """Return ``float(np.median(values))`` of a 1-D series (integers or floats).

    Args:
        values: (N,) numbers.
    """
    x = np.asarray(values)
    n = x.size
    inexact = x.dtype.kind in "fc"
    if n == 0 or x.ndim != 1 or x.dtype.kind not in "iuf":
        return float(np.median(x))  # NumPy's own warning and result for the unusual cases
    half = n // 2
    kth = [half - 1, half] if n % 2 == 0 else [(n - 1) // 2]
    if inexact:
        kth.append(-1)  # NumPy's NaN check: a NaN sorts last
    part = np.partition(x, kth)
    if inexact and np.isnan(part[-1]):
        return float("nan")
    # NumPy's mean adds to 0.0 first (so -0.0 comes out as 0.0), then divides by the count.
    if n % 2:
        return 0.0 + float(part[half])
    return (0.0 + float(part[half - 1]) + float(part[half])) / 2.0


def quantiles(values: ArrayLike, q: Sequence[float]) -> FloatArray:
    """Return ``np.quantile(values, q)`` (linear method) of a 1-D float series.

    Args:
        values: (N,) numbers, N ≥ 1.
        q: the probabilities, each in [0, 1].

    Returns:
        (len(q),) float64 quantiles.
    """
    x = np.array(values, dtype=np.float64).ravel()
    n = x.size
    if n == 0:
        out: FloatArray = np.quantile(x, q)
        return out
    virtual = (n - 1) * np.asarray(q, dtype=np.float64)
    previous = np.floor(virtual)
    following = previous + 1
    above = virtual >= n - 1
    previous[above] = -1
    following[above] = -1
    previous[virtual < 0] = 0
    following[virtual < 0] = 0
    prev_i = previous.astype(np.intp)
    next_i = following.astype(np.intp)
    kth = sorted({0, -1, *prev_i.tolist(), *next_i.tolist()})
    x.partition(kth)
    if np.isnan(x[-1]):
        return np.full(virtual.shape, np.nan)
    gamma = np.asarray(virtual - prev_i, dtype=np.float64)
    a, b = x[prev_i], x[next_i]
    diff = b - a
    result: FloatArray = np.add(a, diff * gamma)
    np.subtract(b, diff * (1 - gamma), out=result, where=gamma >= 0.5)
    return result
