"""Points along the plan's wall segments, evenly spaced (for indexes and coverage)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from loceval.core.arrays import FloatArray

__all__ = ["sample_segments"]


def sample_segments(
    segments_xy: FloatArray, spacing_m: float
) -> tuple[FloatArray, NDArray[np.intp]]:
    """Sample segments every ``spacing_m`` (both ends included).

    Args:
        segments_xy: (K, 2, 2) segment end points, metres.
        spacing_m: the largest distance between neighbouring samples of a segment.

    Returns:
        (S, 2) samples and (S,) the index of each sample's segment.
    """
    a, b = segments_xy[:, 0], segments_xy[:, 1]
    lengths = np.linalg.norm(b - a, axis=1)
    counts = np.ceil(lengths / spacing_m).astype(np.intp) + 1
    owner = np.repeat(np.arange(len(segments_xy)), counts)
    first = np.cumsum(counts) - counts
    step = np.arange(len(owner)) - np.repeat(first, counts)
    t = step / np.maximum(np.repeat(counts, counts) - 1, 1)
    samples: FloatArray = a[owner] + t[:, None] * (b - a)[owner]
    return samples, owner
