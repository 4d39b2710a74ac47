"""Model placement shared by the CAD exporters: site transform, units, simplification.

Every CAD file shows the same thing: the reference and each aligned estimate as polylines,
one per continuous piece (a path breaks at the reference's tracking loss and at its own,
:func:`loceval.gaps.path_breaks`, so no straight chord is drawn across a stretch nobody
measured), each estimate also cut into runs coloured by its ATE (:meth:`Placement.ate_runs`
in the report's colours, :func:`ate_bins`), and one marker per tracking loss. Paths are
mapped from the evaluation frame (the reference's frame, REP 103, Z up, metres) into the
building model's coordinates by the site transform, scaled to the output units and thinned
by Ramer-Douglas-Peucker within a tolerance. :func:`place_evaluation` computes that
view once; ``dxf``, ``rhino`` and ``gltf`` only encode it.

Large site coordinates (a national grid easting of 500 km) stay exact: the geometry is also
kept relative to a base point (the centre of the reference's bounding box in model
coordinates, rounded to whole metres), which the formats with single-precision vertices
(glTF) carry in a node matrix. DXF and 3DM store
doubles and get absolute model coordinates, so they drop onto the building model as they are.
"""

from __future__ import annotations

import colorsys
import itertools
import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Final, TypeAlias

import numpy as np
from scipy.spatial.transform import Rotation

from exporters.building import georeferenced_options
from exporters.errors import ExportOptionsError
from exporters.options import ExportOptions, Units
from loceval import __version__
from loceval._typing import BoolArray, FloatArray, IntArray, StampsNs
from loceval.errors import InputError
from loceval.evaluation import EstimateResult, EvaluationResult
from loceval.gaps import path_breaks
from loceval.geometry import SimilarityTransform
from loceval.polyline import simplify_rdp

__all__ = [
    "BUILDING_SUFFIXES",
    "PALETTE",
    "ATEBin",
    "ATERun",
    "Marker",
    "PathKind",
    "PlacedPath",
    "Placement",
    "ate_bins",
    "ate_edges_m",
    "check_options",
    "layer_name",
    "palette_color",
    "parse_site",
    "parse_units",
    "place_evaluation",
    "read_site_matrix",
    "site_from_values",
]

RGB: TypeAlias = tuple[int, int, int]

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

SITE_FORMAT: Final = '"tx ty tz yaw_deg"'
BUILDING_SUFFIXES: Final = (".obj", ".ply", ".stl", ".glb", ".ifc")
"""Building model formats accepted (read by :mod:`exporters.building`)."""
_NS_PER_S: Final = 1_000_000_000
_WORST_SEPARATION_S: Final = 2.0  # greatest errors closer in time than this share a marker
_INVALID_LAYER_CHARS: Final = re.compile(r'[<>/\\":;?*|=,`\[\]{}\x00-\x1f\x7f]+')
_BIN_COLORS: Final[tuple[RGB, ...]] = ((0, 170, 0), (230, 200, 0), (255, 120, 0), (220, 0, 0))
_MAX_EXTRA_EDGES: Final = 4  # at most this many 1-2-5 edges above the last threshold
_MARKER_MERGE_SHARE: Final = 0.05  # losses closer than 5 % of the drawing share a marker


class PathKind(StrEnum):
    """What a placed polyline shows."""

    REFERENCE = "reference"
    ESTIMATE = "estimate"


# --- options -------------------------------------------------------------------------------


def parse_units(text: str) -> Units:
    """Parse the CAD units (``mm``, ``cm`` or ``m``).

    Raises:
        ExportOptionsError: another unit.
    """
    try:
        return Units(text.strip().lower())
    except ValueError:
        choices = ", ".join(u.value for u in Units)
        msg = f"The CAD units must be one of {choices}, got {text!r}."
        raise ExportOptionsError(msg, option="units") from None


def parse_site(text: str) -> SimilarityTransform:
    """Parse a site ``"tx ty tz yaw_deg"`` into the evaluation-frame -> model transform.

    The translation is in metres (model coordinates of the evaluation frame's origin) and
    the yaw is a rotation about Z in degrees, counter-clockwise seen from above. ``"tx ty
    tz"`` alone means no rotation. Commas may separate the numbers.

    Raises:
        ExportOptionsError: not three or four finite numbers.
    """
    try:
        values = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        values = []
    if len(values) not in (3, 4) or not all(math.isfinite(v) for v in values):
        msg = (
            f"The site transform takes {SITE_FORMAT} (metres, degrees about Z), for example "
            f'"512340.0 5403210.5 112.3 37.5", got {text!r}.'
        )
        raise ExportOptionsError(msg, option="site")
    yaw_deg = values[3] if len(values) == 4 else 0.0
    rotation = Rotation.from_euler("z", yaw_deg, degrees=True).as_matrix()
    return SimilarityTransform(rotation, np.array(values[:3]), 1.0)


def read_site_matrix(path: Path) -> SimilarityTransform:
    """Read a 4x4 evaluation-frame -> model matrix from a text or JSON file.

    Accepted forms, all row-major ``[[sR, t], [0, 0, 0, 1]]`` with ``t`` in metres: 16
    numbers in a text file (whitespace, comma or semicolon separated, ``#`` comments), or a
    JSON array of 4 rows, a flat JSON array of 16, or a JSON object with either under
    ``"matrix"``. A uniform scale is allowed; shear, reflection and singular matrices are not.

    Raises:
        ExportOptionsError: the file is unreadable or the matrix is not a similarity transform.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        msg = f"Cannot read the site matrix file {str(path)!r} ({err}); check the path."
        raise ExportOptionsError(msg, option="site_matrix") from err
    return site_from_values(_matrix_numbers(text), where=f"the site matrix file {str(path)!r}")


def site_from_values(values: Sequence[float] | None, *, where: str) -> SimilarityTransform:
    """Return the site transform of 16 row-major numbers (see :func:`read_site_matrix`).

    Args:
        values: the numbers, or None when they could not be read.
        where: names the matrix in messages (``"the site matrix file 'site.txt'"``).

    Raises:
        ExportOptionsError: not 16 finite numbers, or not a similarity transform.
    """
    if values is None or len(values) != 16 or not all(math.isfinite(v) for v in values):
        msg = (
            f"{where[0].upper()}{where[1:]} must hold 16 numbers (a 4x4 row-major "
            "matrix, or JSON [[...], [...], [...], [...]]); check its contents."
        )
        raise ExportOptionsError(msg, option="site_matrix")
    matrix = np.array(values, dtype=np.float64).reshape(4, 4)
    if not np.allclose(matrix[3], [0.0, 0.0, 0.0, 1.0]) and np.allclose(
        matrix[:, 3], [0.0, 0.0, 0.0, 1.0]
    ):
        msg = (
            f"The matrix of {where} looks column-major (glTF/three.js order); "
            "write it row by row with the translation in the last column."
        )
        raise ExportOptionsError(msg, option="site_matrix")
    det = float(np.linalg.det(matrix[:3, :3]))
    if abs(det) < 1e-12:
        msg = f"The matrix of {where} is singular (det={det:.3g}); check its values."
        raise ExportOptionsError(msg, option="site_matrix")
    try:
        return SimilarityTransform.from_matrix(matrix)
    except InputError as err:
        msg = (
            f"The matrix of {where} is not a rotation with uniform scale and a "
            f"translation ({err}); check its values."
        )
        raise ExportOptionsError(msg, option="site_matrix") from err


def _matrix_numbers(text: str) -> list[float] | None:
    stripped = text.strip()
    if stripped.startswith(("[", "{")):
        try:
            document = json.loads(stripped)
        except json.JSONDecodeError:
            return None
        if isinstance(document, dict):
            document = document.get("matrix")
        flat = np.asarray(document, dtype=object).reshape(-1).tolist() if document else []
        try:
            return [float(v) for v in flat]
        except (TypeError, ValueError):
            return None
    lines = (line.split("#", 1)[0] for line in text.splitlines())
    tokens = re.split(r"[\s,;]+", " ".join(lines).strip())
    try:
        return [float(t) for t in tokens if t]
    except ValueError:
        return None


def check_options(options: ExportOptions) -> None:
    """Check the placement options a user can get wrong (cheap: reads no file).

    Raises:
        ExportOptionsError: unknown units, a negative or non-finite simplification, or a
            building file that is missing or not an OBJ, PLY, STL or GLB.
    """
    parse_units(str(options.units))  # a plain string passed for Units must still be valid
    if not (math.isfinite(options.simplify_m) and options.simplify_m >= 0.0):
        msg = (
            f"The simplification tolerance must be zero or a positive number of metres, got "
            f"{options.simplify_m!r}; use 0 to keep every pose."
        )
        raise ExportOptionsError(msg, option="simplify_m")
    building = options.building
    if building is not None:
        if building.suffix.lower() not in BUILDING_SUFFIXES:
            kinds = ", ".join(s.lstrip(".").upper() for s in BUILDING_SUFFIXES)
            msg = (
                f"The building model {str(building)!r} is not a supported mesh; export it "
                f"as {kinds}."
            )
            raise ExportOptionsError(msg, option="building")
        if not building.is_file():
            msg = f"The building model {str(building)!r} does not exist; check the path."
            raise ExportOptionsError(msg, option="building")


# --- names and colours -----------------------------------------------------------------


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
    layer paths (``::``, brackets, braces) become ``_``; the result is at most 200
    characters and never empty.
    """
    cleaned = _INVALID_LAYER_CHARS.sub("_", name).strip()[:200].strip()
    return cleaned or "unnamed"


def _unique_names(names: Sequence[str]) -> list[str]:
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


# --- the placed view -------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class PlacedPath:
    """One trajectory as a polyline in model coordinates.

    Attributes:
        name: the trajectory's name, unique among the paths of a placement.
        kind: reference or estimate.
        source: where the trajectory came from (file, topic or tf chain).
        layer: ``name`` made valid as a layer name in every format.
        color_rgb: 0-255 sRGB colour from the palette.
        stamps_ns: (M,) stamps of the kept vertices.
        vertices: (M, 3) float64 model coordinates in the output units, the pieces one
            after the other.
        local_vertices: (M, 3) float64 ``vertices`` minus the placement's base point.
        errors_m: (M,) ATE translation at the kept vertices (None for the reference).
        poses: vertex count before simplification.
        max_deviation_m: largest deviation the simplification introduced, metres.
        estimate: the estimate's result (None for the reference).
        piece_starts: (P,) index into ``vertices`` where each continuous piece starts
            (the first is 0); a path breaks at tracking loss, its own or the reference's.
    """

    name: str
    kind: PathKind
    source: str
    layer: str
    color_rgb: RGB
    stamps_ns: StampsNs
    vertices: FloatArray
    local_vertices: FloatArray
    errors_m: FloatArray | None
    poses: int
    max_deviation_m: float
    estimate: EstimateResult | None
    piece_starts: IntArray

    def pieces(self) -> list[tuple[int, int]]:
        """Return ``(start, stop)`` of every continuous piece in ``vertices`` (stop exclusive)."""
        stops = [*self.piece_starts[1:].tolist(), len(self.vertices)]
        return list(zip(self.piece_starts.tolist(), stops, strict=True))

    @property
    def color_hex(self) -> str:
        """Return the colour as ``#rrggbb``."""
        r, g, b = self.color_rgb
        return f"#{r:02x}{g:02x}{b:02x}"

    def metadata(self) -> dict[str, object]:
        """Return what every format stores about this path (JSON-ready)."""
        ate = None if self.estimate is None else self.estimate.ate_translation.stats.to_dict()
        return {
            "name": self.name,
            "kind": self.kind.value,
            "source": self.source,
            "layer": self.layer,
            "color": list(self.color_rgb),
            "color_hex": self.color_hex,
            "poses": self.poses,
            "vertices": len(self.vertices),
            "pieces": len(self.piece_starts),
            "max_deviation_m": self.max_deviation_m,
            "ate_translation_m": ate,
        }


@dataclass(frozen=True, slots=True)
class Marker:
    """A point worth labelling: a greatest error or a tracking loss.

    Attributes:
        path: name of the path it belongs to.
        kind: ``"worst"`` (a greatest ATE, at the estimate pose) or ``"gap"`` (the last
            pose before a tracking loss: of the reference, or of an estimate where the
            reference kept tracking).
        position: (x, y, z) model coordinates in the output units.
        target: for ``"worst"``, the reference position the error is measured to.
        label: the text to show.
    """

    path: str
    kind: str
    position: tuple[float, float, float]
    target: tuple[float, float, float] | None
    label: str


@dataclass(frozen=True, slots=True)
class ATEBin:
    """A range of ATE translation errors drawn in one colour.

    Attributes:
        low_m: lower bound (exclusive, except 0), metres.
        high_m: upper bound (inclusive), metres; ``inf`` for the last bin.
        color_rgb: its colour.
        label: legend text (``"0.05-0.10 m"``).
    """

    low_m: float
    high_m: float
    color_rgb: RGB
    label: str


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
        if k == 0:
            label = f"<= {high:g} m"
        elif math.isinf(high):
            label = f"> {low:g} m"
        else:
            label = f"{low:g}-{high:g} m"
        bins.append(ATEBin(low, high, color, label))
    return tuple(bins)


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
class Placement:
    """The polylines of one evaluation in model coordinates (what every CAD file shows).

    Attributes:
        result: the evaluation.
        units: output length units.
        site: evaluation frame (metres) -> model coordinates (metres).
        base_point_m: (3,) model coordinates, metres, that local vertices are relative to
            (the reference's bounding-box centre rounded to whole metres).
        simplify_m: the simplification tolerance, metres.
        evaluation_id: the evaluation's id.
        title: a human title.
        paths: the reference first, then the estimates in evaluation order.
    """

    result: EvaluationResult
    units: Units
    site: SimilarityTransform
    base_point_m: FloatArray
    simplify_m: float
    evaluation_id: str
    title: str
    paths: tuple[PlacedPath, ...]

    @property
    def base_point(self) -> FloatArray:
        """Return the base point in model coordinates, output units, (3,)."""
        out: FloatArray = self.base_point_m * self.units.per_metre
        return out

    @property
    def max_deviation_m(self) -> float:
        """Return the largest simplification deviation over all paths, metres."""
        return max((p.max_deviation_m for p in self.paths), default=0.0)

    @property
    def frame(self) -> str:
        """Return the evaluation frame's name (the reference's frame)."""
        return self.result.reference.frame_id or "reference frame"

    def to_model(self, positions_xyz: FloatArray) -> FloatArray:
        """Map (N, 3) evaluation-frame metres to model coordinates in the output units."""
        out: FloatArray = self.site.apply_positions(positions_xyz) * self.units.per_metre
        return out

    def metadata(self) -> dict[str, object]:
        """Return the file-level metadata every format stores (JSON-ready)."""
        return {
            "generator": f"loceval {__version__}",
            "evaluation_id": self.evaluation_id,
            "title": self.title,
            "created_at": self.result.created_at,
            "units": self.units.value,
            "frame": {
                "evaluation_frame": self.frame,
                "convention": "REP 103: x forward, y left, z up, metres",
                "model": "building model coordinates, z up",
                "site_matrix_m": self.site.as_matrix().tolist(),
            },
            "base_point": self.base_point.tolist(),
            "simplify_tolerance_m": self.simplify_m,
            "max_deviation_m": self.max_deviation_m,
            "paths": [p.name for p in self.paths],
        }

    def ate_bins(self) -> tuple[ATEBin, ...]:
        """Return the ATE colour bins every output uses (:func:`ate_edges_m`)."""
        return ate_bins(ate_edges_m(self.result))

    def ate_runs(self, path: PlacedPath) -> list[ATERun]:
        """Return an estimate's path cut where its ATE changes bin, each run simplified.

        Runs never cross a break of the path (tracking loss); within one piece they join.
        The reference (no ATE) has none.
        """
        est = path.estimate
        if est is None or len(est.aligned) == 0:
            return []
        bins = self.ate_bins()
        edges = np.array([b.high_m for b in bins[:-1]])
        which = np.searchsorted(edges, est.ate_translation.values, side="left")
        model = self.to_model(est.aligned.positions_xyz)
        jump = _jumps(self.result, est.aligned.stamps_ns)
        piece = np.concatenate(([0], np.cumsum(jump)))
        change = (np.diff(which) != 0) | jump
        starts = np.concatenate(([0], np.flatnonzero(change) + 1))
        ends = np.concatenate((starts[1:], [len(which)]))
        # a run continues to the next run's first vertex unless a break lies between
        ends = np.where((ends < len(which)) & ~np.append(jump, True)[ends - 1], ends + 1, ends)
        tolerance = self.simplify_m * self.units.per_metre
        base = self.base_point
        runs = []
        for start, stop in zip(starts.tolist(), ends.tolist(), strict=True):  # per run
            if stop - start < 2:
                continue
            chunk = model[start:stop]
            kept, _ = simplify_rdp(chunk, tolerance)
            runs.append(
                ATERun(
                    path=path.name,
                    piece=int(piece[start]),
                    bin_index=int(which[start]),
                    vertices=chunk[kept],
                    local_vertices=chunk[kept] - base,
                )
            )
        return runs

    def markers(self) -> list[Marker]:
        """Return one marker per tracking loss and the greatest-error markers.

        A tracking loss of the reference is marked once (at its last pose before the
        loss), not once per trajectory; an estimate's own loss is marked where the
        reference kept tracking. Losses whose markers lie within 5 % of the drawing's size
        of each other share one, labelled by the longest; greatest errors closer than 2 s
        to a greater one are left out (one excursion). Their labels would only pile up.
        """
        out = self._gap_markers()
        for path in self.paths:
            est = path.estimate
            if est is None:
                continue
            labelled: list[float] = []
            for rank, worst in enumerate(est.worst, start=1):
                # the greatest errors come in bursts of neighbouring poses: one marker each
                if any(abs(worst.t_s - t) < _WORST_SEPARATION_S for t in labelled):
                    continue
                labelled.append(worst.t_s)
                here = self.to_model(est.aligned.positions_xyz[worst.index : worst.index + 1])
                there = self.to_model(np.array([worst.position_xyz]))
                out.append(
                    Marker(
                        path=path.name,
                        kind="worst",
                        position=_xyz(here[0]),
                        target=_xyz(there[0]),
                        label=(
                            f"{path.name} #{rank}: ATE {worst.error:.3f} m at t={worst.t_s:.1f} s"
                        ),
                    )
                )
        return out

    def _gap_markers(self) -> list[Marker]:
        min_gap_ns = round(self.result.config.max_gap_s * _NS_PER_S)
        reference = self.result.reference
        ref_losses = reference.tracking_losses(min_gap_ns)
        t0 = int(reference.stamps_ns[0])
        out: list[Marker] = []
        for path in self.paths:
            est = path.estimate
            trajectory = reference if est is None else est.aligned
            if est is None:
                losses = ref_losses
            else:  # its own losses where the reference kept tracking
                own = path_breaks(trajectory.stamps_ns, min_gap_ns=min_gap_ns)
                seen = path_breaks(trajectory.stamps_ns, min_gap_ns=10**18, losses=ref_losses)
                idx = np.flatnonzero(own & ~seen)
                losses = [
                    (int(trajectory.stamps_ns[i]), int(trajectory.stamps_ns[i + 1])) for i in idx
                ]
            if not losses:
                continue
            where = np.searchsorted(trajectory.stamps_ns, [a for a, _ in losses])
            positions = self.to_model(trajectory.positions_xyz[where])
            for group in _group_losses(losses, positions, self._marker_radius()):
                # labelled by its longest loss, placed at that loss's last pose before it
                k = max(group, key=lambda i: losses[i][1] - losses[i][0])
                start, end = losses[k]
                from_s = (start - t0) / _NS_PER_S
                # the reference's losses are everyone's: only an estimate's own is named
                who = "" if est is None else f"{path.name}: "
                label = f"{who}no pose for {(end - start) / _NS_PER_S:.1f} s from t={from_s:.1f} s"
                if len(group) > 1:
                    label += f" (+{len(group) - 1} nearby)"
                out.append(
                    Marker(
                        path=path.name,
                        kind="gap",
                        position=_xyz(positions[k]),
                        target=None,
                        label=label,
                    )
                )
        return out

    def _marker_radius(self) -> float:
        """Return the distance, in output units, within which loss markers share one."""
        vertices = np.concatenate([p.vertices for p in self.paths])
        diagonal = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
        return _MARKER_MERGE_SHARE * diagonal


def _group_losses(
    losses: Sequence[tuple[int, int]], positions: FloatArray, radius: float
) -> list[list[int]]:
    """Group losses whose markers would lie within ``radius`` of a longer loss's marker.

    Losses at one spot (a body that keeps leaving the cameras' view at the same corner)
    would draw their labels on top of each other; they share one marker instead.
    """
    groups: list[list[int]] = []
    longest_first = sorted(range(len(losses)), key=lambda i: losses[i][0] - losses[i][1])
    for i in longest_first:  # one iteration per tracking loss, not per pose
        near = next(
            (g for g in groups if np.linalg.norm(positions[i] - positions[g[0]]) <= radius),
            None,
        )
        if near is None:
            groups.append([i])
        else:
            near.append(i)
    return sorted(groups, key=lambda g: losses[g[0]][0])  # in time order of their anchors


def _jumps(result: EvaluationResult, stamps_ns: StampsNs) -> BoolArray:
    """Return (N - 1,) where a path through these stamps breaks (:func:`path_breaks`)."""
    min_gap_ns = round(result.config.max_gap_s * _NS_PER_S)
    losses = result.reference.tracking_losses(min_gap_ns)
    return path_breaks(stamps_ns, min_gap_ns=min_gap_ns, losses=losses)


def _xyz(row: FloatArray) -> tuple[float, float, float]:
    return float(row[0]), float(row[1]), float(row[2])


def place_evaluation(result: EvaluationResult, options: ExportOptions) -> Placement:
    """Map, scale and simplify every trajectory of an evaluation for the CAD exporters.

    The reference comes first (cyan), then each aligned estimate (magenta, green, ...). Each
    is mapped by ``options.site``, simplified in model metres within ``options.simplify_m``
    and scaled to ``options.units``.

    Args:
        result: the evaluation.
        options: units, site transform, tolerance, ids.

    Returns:
        The placement.

    Raises:
        ExportOptionsError: unknown units or a negative tolerance.
    """
    check_options(options)
    options = georeferenced_options(options)  # an IFC building's own site, if none is given
    units = Units(options.units)
    site = options.site
    # the base point: the reference's bounding-box centre in model metres, rounded so it
    # reads well in metadata; it works for a far site translation and for a reference
    # already given in a national grid alike
    ref_model_m = site.apply_positions(result.reference.positions_xyz)
    base_m = np.round((ref_model_m.min(axis=0) + ref_model_m.max(axis=0)) / 2.0)
    reference = result.reference
    sources = [(reference, None), *((e.aligned, e) for e in result.estimates)]
    names = [reference.name or "reference"]
    names += [e.name or f"estimate {k}" for k, e in enumerate(result.estimates, start=1)]
    layers = _unique_names([layer_name(n) for n in names])
    paths = []
    for k, ((trajectory, est), layer) in enumerate(zip(sources, layers, strict=True)):
        model_m = site.apply_positions(trajectory.positions_xyz)
        kept, piece_starts, deviation = _simplify_pieces(
            model_m, _jumps(result, trajectory.stamps_ns), options.simplify_m
        )
        vertices = model_m[kept] * units.per_metre
        local = (model_m[kept] - base_m) * units.per_metre
        name = names[k] if layer == layer_name(names[k]) else layer
        paths.append(
            PlacedPath(
                name=name,
                kind=PathKind.REFERENCE if est is None else PathKind.ESTIMATE,
                source=trajectory.source if est is None else est.estimate.source,
                layer=layer,
                color_rgb=palette_color(k),
                stamps_ns=trajectory.stamps_ns[kept],
                vertices=vertices,
                local_vertices=local,
                errors_m=None if est is None else est.ate_translation.values[kept],
                poses=len(trajectory),
                max_deviation_m=deviation,
                estimate=est,
                piece_starts=piece_starts,
            )
        )
    return Placement(
        result=result,
        units=units,
        site=site,
        base_point_m=base_m,
        simplify_m=float(options.simplify_m),
        evaluation_id=options.evaluation_id,
        title=options.title,
        paths=tuple(paths),
    )


def _simplify_pieces(
    model_m: FloatArray, jump: BoolArray, tolerance_m: float
) -> tuple[IntArray, IntArray, float]:
    """Simplify each continuous piece on its own; return kept indices, piece starts, deviation.

    Args:
        model_m: (N, 3) model coordinates, metres.
        jump: (N - 1,) True after each pose that ends a piece.
        tolerance_m: the simplification tolerance, metres.

    Returns:
        The (M,) kept indices into ``model_m``, the (P,) indices into the kept vertices
        where each piece starts, and the largest deviation introduced.
    """
    n = int(model_m.shape[0])
    bounds = [0, *(np.flatnonzero(jump) + 1).tolist(), n]
    kept_parts: list[IntArray] = []
    starts: list[int] = []
    deviation = 0.0
    count = 0
    for a, b in itertools.pairwise(bounds):  # one iteration per piece (tracking losses + 1)
        if b <= a:
            continue
        kept, dev = simplify_rdp(model_m[a:b], tolerance_m)
        kept_parts.append(kept + a)
        starts.append(count)
        count += int(kept.shape[0])
        deviation = max(deviation, dev)
    kept_all = np.concatenate(kept_parts) if kept_parts else np.zeros(0, dtype=np.intp)
    return kept_all.astype(np.intp), np.asarray(starts, dtype=np.intp), deviation
