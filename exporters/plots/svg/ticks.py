"""Axis limits and ticks: round steps (1, 2, 2.5, 5 times a power of ten) and their labels."""

from __future__ import annotations

import math
from typing import Final

import numpy as np

from loceval.core.arrays import FloatArray

__all__ = ["MINUS", "format_ticks", "nice_ticks", "padded_limits"]

MINUS: Final = "\u2212"
"""The typographic minus of tick labels (matplotlib's too), not a hyphen."""
_STEPS: Final = (1.0, 2.0, 2.5, 5.0, 10.0)
MARGIN: Final = 0.05
"""Share of the data range added on each side of an axis' automatic limits."""


def padded_limits(lo: float, hi: float, margin: float = MARGIN) -> tuple[float, float]:
    """Return the automatic limits of data spanning ``lo`` to ``hi``: 5 % of the span beyond.

    A single value gets 5 % of itself on either side (0: ±0.05), as no scale can be read
    from it; no value at all (``lo > hi``) gets 0 to 1. A tiny span is still a span: errors
    of 1e-14 (rounding noise) get limits of that size, which a floor on the axis then
    lifts (``Axes.set_ylim(at_least=...)``).
    """
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
        return 0.0, 1.0
    largest = max(abs(lo), abs(hi))
    if hi - lo <= 1e-15 * largest or largest == 0.0:
        half = 0.05 * largest if largest else 0.05
        return lo - half, hi + half
    pad = margin * (hi - lo)
    return lo - pad, hi + pad


def nice_ticks(lo: float, hi: float, max_ticks: int) -> tuple[FloatArray, float]:
    """Return the round tick values within ``[lo, hi]`` and their step.

    The step is the smallest of 1, 2, 2.5 and 5 times a power of ten that puts at most
    ``max_ticks`` ticks in the range.
    """
    span = hi - lo
    if not (math.isfinite(span) and span > 0):
        return np.array([lo]), 1.0
    raw = span / max(max_ticks - 1, 1)
    power = 10.0 ** math.floor(math.log10(raw))
    step = next(s * power for s in _STEPS if s * power >= raw * (1 - 1e-9))
    first = math.ceil(lo / step - 1e-9)
    last = math.floor(hi / step + 1e-9)
    values = np.arange(first, last + 1, dtype=np.float64) * step
    values[np.abs(values) < 1e-12 * step] = 0.0
    return values, step


def format_ticks(values: FloatArray, step: float) -> list[str]:
    """Return the tick labels: as many decimals as the step needs, the same for each."""
    decimals = 0
    while decimals < 12 and abs(round(step, decimals) - step) > 1e-9 * step:
        decimals += 1
    return [f"{v:.{decimals}f}".replace("-", MINUS) for v in values.tolist()]
