"""The colours and names every output shares: the trajectory palette, layer names, ATE bins.

Every picture of the errors (the viewer, the report's figures, the DXF, .3dm, GLB and IFC
ATE layers, the Grasshopper document and Hops) colours a path's ATE with the same bins
(:func:`error_bins`), so a site engineer reads one legend everywhere. With a tolerance the
scale is anchored to it (:func:`tolerance_bins`): two shades of green within it, orange to
red by how far beyond; without one, the threshold bands (:func:`ate_bins`,
:func:`ate_edges_m`).
"""

from __future__ import annotations

import colorsys
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final, TypeAlias

import numpy as np

from loceval.core.arrays import FloatArray
from loceval.core.display import display_text
from loceval.core.lengths import LengthUnit, length_unit
from loceval.core.quantities import AT_MOST
from loceval.evaluation import EvaluationResult

RGB: TypeAlias = tuple[int, int, int]
_MORE_EDGES_M: Final = (0.25, 0.5, 1.0, 2.0)
"""Map colour edges added above the thresholds while the map's cells lie farther."""


PALETTE: Final[tuple[RGB, ...]] = (
    (0, 255, 255),  # ground truth: cyan, as in the framework paper's Fig. 5
    (255, 0, 255),  # first estimate: magenta (RTAB-Map in Fig. 5)
    (0, 200, 0),  # second estimate: green (ISAAC in Fig. 5)
    (255, 140, 0),  # orange
    (0, 90, 255),  # blue
    (220, 20, 60),  # crimson
    (150, 90, 40),  # brown
    (140, 60, 255),  # violet
    (200, 180, 0),  # olive yellow
    (110, 110, 110),  # grey
)
"""Trajectory colours in order: the reference first, then the estimates."""

ESTIMATE_COLOURS: tuple[str, ...] = (
    "#d4009a",  # magenta (RTAB-Map in the framework paper's Fig. 5)
    "#1f9e34",  # green (ISAAC in the framework paper's Fig. 5)
    "#f58a07",  # orange
    "#3b4cc0",  # blue
    "#8c564b",  # brown
    "#6b6b6b",  # grey
    "#b8a700",  # olive
    "#7b2cbf",  # violet
)
"""Distinct estimate colours in order of the estimates."""


def estimate_colour(index: int) -> str:
    """Return the colour of the ``index``-th estimate (cycling after eight)."""
    return ESTIMATE_COLOURS[index % len(ESTIMATE_COLOURS)]


_INVALID_LAYER_CHARS: Final = re.compile(r'[<>/\\":;?*|=,`\[\]{}\x00-\x1f\x7f\ufffd]+')
_BIN_COLORS: Final[tuple[RGB, ...]] = ((0, 170, 0), (230, 200, 0), (255, 120, 0), (220, 0, 0))
_MAX_EXTRA_EDGES: Final = 4  # at most this many 1-2-5 edges above the last threshold


# --- names and colours -----------------------------------------------------------------


def hex_colour(rgb: RGB) -> str:
    """Return an RGB colour as ``#rrggbb``."""
    return "#{:02x}{:02x}{:02x}".format(*rgb)


def palette_color(index: int) -> RGB:
    """Return colour ``index`` of the palette (0: the reference), inventing distinct ones after.

    Colours past the fixed palette step around the hue circle by the golden angle.
    """
    if index < len(PALETTE):
        return PALETTE[index]
    hue = (index * 0.618033988749895) % 1.0
    r, g, b = colorsys.hsv_to_rgb(hue, 0.85, 0.85)
    return round(r * 255), round(g * 255), round(b * 255)


def layer_name(name: str) -> str:
    r"""Return ``name`` made valid as a DXF, Rhino and glTF layer/node name.

    Characters that DXF forbids in table names (``<>/\\":;?*|=,```) or that Rhino uses in
    layer paths (``::``, brackets, braces) become ``_``, as do control characters and
    bidirectional overrides (:func:`~loceval.core.display.display_text`); the result is at most 200
    characters and never empty.
    """
    cleaned = _INVALID_LAYER_CHARS.sub("_", display_text(name)).strip()[:200].strip()
    return cleaned or "unnamed"


def unique_layer_names(names: Sequence[str]) -> list[str]:
    """Make layer names unique, ignoring case (DXF layer names are case-insensitive)."""
    seen: set[str] = set()
    out = []
    for name in names:
        candidate, k = name, 2
        while candidate.casefold() in seen:
            candidate = f"{name} ({k})"
            k += 1
        seen.add(candidate.casefold())
        out.append(candidate)
    return out


@dataclass(frozen=True, slots=True)
class ATEBin:
    """A range of ATE translation errors drawn in one colour.

    Attributes:
        low_m: lower bound (exclusive, except 0), metres.
        high_m: upper bound (inclusive), metres; ``inf`` for the last bin.
        color_rgb: its colour.
        label: legend text (``"0.05-0.10 m"``).
        beyond: errors in it exceed the tolerance (a tolerance-anchored scale).
    """

    low_m: float
    high_m: float
    color_rgb: RGB
    label: str
    beyond: bool = False


def ate_bins(thresholds_m: Sequence[float]) -> tuple[ATEBin, ...]:
    """Return the error bins of these edges, green (small) to red (large).

    The one colour scale of ATE in every output: the report's error-coloured paths, the
    DXF's ATE layers, the .3dm's coloured segments and the GLB's vertex colours.
    """
    edges = sorted({float(t) for t in thresholds_m})
    bounds = [0.0, *edges, math.inf]
    count = len(bounds) - 1
    bins = []
    for k in range(count):
        # spread the bins evenly over the green -> yellow -> orange -> red ramp
        color = _ramp(0.0 if count == 1 else k / (count - 1))
        low, high = bounds[k], bounds[k + 1]
        bins.append(ATEBin(low, high, color, _bin_label(low, high, first=k == 0)))
    return tuple(bins)


def _bin_label(low_m: float, high_m: float, *, first: bool) -> str:
    """Return a bin's legend text: ``≤ 0.05 m`` (the first), ``0.05-0.1 m`` or ``> 0.15 m``."""
    if first:
        return f"{AT_MOST} {high_m:g} m"
    if math.isinf(high_m):
        return f"> {low_m:g} m"
    return f"{low_m:g}-{high_m:g} m"


_WITHIN_RGB: Final[tuple[RGB, ...]] = ((0, 122, 61), (120, 200, 80))
"""Within the tolerance: dark green up to half of it, light green up to it."""
_BEYOND_RGB: Final[tuple[RGB, ...]] = ((255, 170, 0), (240, 95, 0), (200, 0, 0))
"""Beyond it: orange up to 1.5 times it, dark orange up to twice, red past that."""
_BEYOND_FACTORS: Final = (1.5, 2.0)


def tolerance_bins(distance_m: float) -> tuple[ATEBin, ...]:
    """Return the colour scale anchored to a tolerance: green within, orange to red beyond.

    Bins: ``<= t/2`` and ``t/2-t`` (shades of green, within), ``t-1.5t``, ``1.5t-2t`` and
    ``> 2t`` (orange, dark orange, red: beyond, by how far). Their upper bounds are
    inclusive, as the tolerance's "within" is (an error equal to it is within).
    """
    t = float(distance_m)
    edges = [0.0, t / 2.0, t, *(f * t for f in _BEYOND_FACTORS), math.inf]
    colours = [*_WITHIN_RGB, *_BEYOND_RGB]
    bins = []
    for k, rgb in enumerate(colours):
        low, high = edges[k], edges[k + 1]
        label = _bin_label(low, high, first=k == 0)
        bins.append(ATEBin(low, high, rgb, label, beyond=k >= len(_WITHIN_RGB)))
    return tuple(bins)


def error_bins(result: EvaluationResult) -> tuple[ATEBin, ...]:
    """Return the one ATE colour scale of an evaluation's every picture of its errors.

    Anchored to the tolerance when one was given (:func:`tolerance_bins`), else the
    threshold bands widened to the errors' range (:func:`ate_bins` of :func:`ate_edges_m`).
    """
    tolerance = result.config.tolerance
    if tolerance is not None:
        return tolerance_bins(tolerance.distance_m)
    return ate_bins(ate_edges_m(result))


def error_unit(result: EvaluationResult) -> LengthUnit:
    """Return the unit every label of this evaluation's errors reads in (viewer, CAD files).

    One group (:func:`loceval.core.lengths.length_unit`): the largest error of each
    estimate; millimetres when all are below 0.1 m.
    """
    return length_unit(
        float(e.ate_translation.values.max()) for e in result.estimates if len(e.ate_translation)
    )


def scale_words(result: EvaluationResult) -> str:
    """Return the legend's sentence: what the colours mean, the tolerance in words."""
    tolerance = result.config.tolerance
    if tolerance is None:
        return "ATE colours by the report's distance bands (no tolerance given)."
    t = tolerance.distance_m
    return (
        f"Tolerance: within {t:g} m for {tolerance.share * 100:g} % of poses. Green: within "
        f"{t:g} m; orange to red: beyond it (red past {_BEYOND_FACTORS[-1] * t:g} m)."
    )


def _ramp(fraction: float) -> RGB:
    """Return the colour at ``fraction`` (0 to 1) of the green -> red ramp."""
    pos = fraction * (len(_BIN_COLORS) - 1)
    k = min(int(pos), len(_BIN_COLORS) - 2)
    w = pos - k
    a, b = _BIN_COLORS[k], _BIN_COLORS[k + 1]
    r, g, bl = (round((1 - w) * x + w * y) for x, y in zip(a, b, strict=True))
    return r, g, bl


def ate_edges_m(result: EvaluationResult) -> tuple[float, ...]:
    """Return the ATE colour edges of an evaluation: its thresholds, extended upwards.

    The thresholds (0.05, 0.1, 0.15 m by default) tell a good system's errors apart, but a
    car's SLAM with 10 m errors would be one red line, and a motion-capture-grade system
    with 6 mm errors one green line. So when the largest 99.5th percentile of the
    estimates' ATE exceeds twice the last threshold, up to four 1-2-5 edges (0.2, 0.5, 1,
    2, 5 m, ...) are added above it, the last one below that percentile; when it is below
    half the first threshold, up to four 1-2-5 edges from a tenth of it up to it are added
    below the thresholds (fr2_desk: 0.002, 0.005, 0.01 m).
    """
    edges = sorted({float(t) for t in result.config.thresholds_m})
    values = [e.ate_translation.values for e in result.estimates if len(e.ate_translation)]
    if not edges or not values:
        return tuple(edges)
    top = max(float(np.percentile(v, 99.5)) for v in values)
    nice = [m * 10.0**e for e in range(-4, 7) for m in (1.0, 2.0, 5.0)]
    first, last = edges[0], edges[-1]
    if top < 0.5 * first:  # a sub-centimetre system: 1-2-5 edges below the thresholds
        below = [v for v in nice if top / 10.0 <= v < min(top, first / 1.5)]
        return (*below[-_MAX_EXTRA_EDGES:], *edges)
    if top <= 2.0 * last:
        return tuple(edges)
    extra = [v for v in nice if last * 1.5 <= v < top]
    if len(extra) > _MAX_EXTRA_EDGES:  # keep the largest, spread over the range
        pick = np.linspace(0, len(extra) - 1, _MAX_EXTRA_EDGES).round().astype(int)
        extra = [extra[i] for i in pick]
    return (*edges, *extra)


def map_bins(distance_m: FloatArray, thresholds_m: Sequence[float]) -> tuple[ATEBin, ...]:
    """Return the colour bins of a map's wall distances: the thresholds, then 0.25-2 m.

    The same green-to-red scale as the ATE in every output; the edges above the thresholds
    are added while the largest distance lies beyond them.
    """
    edges = sorted({float(t) for t in thresholds_m})
    top = float(distance_m.max()) if len(distance_m) else 0.0
    edges += [e for e in _MORE_EDGES_M if e > (edges[-1] if edges else 0.0) and e < top]
    return ate_bins(edges)


MAP_CELLS_COLUMNS: Final = ("x_m", "y_m", "distance_m", "fitted_distance_m", "clutter")
"""The header of ``map_cells.csv``."""
