"""Model placement shared by the CAD exporters: site transform, units, simplification.

Every CAD file shows the same thing: the reference and each aligned estimate as polylines,
one per continuous piece (a path breaks at the reference's tracking loss and at its own,
:func:`loceval.core.gaps.path_breaks`, so no straight chord is drawn across a stretch nobody
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

from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Final, TypeVar, cast

import numpy as np

from exporters.cad.ate_runs import ATERun, ATERunArrays, cut_ate_runs, no_ate_runs
from exporters.cad.building import FloorPlan, georeferenced_options, read_underlay
from exporters.cad.site import (
    BUILDING_SUFFIXES,
    check_options,
    parse_site,
    parse_units,
    read_site_matrix,
    site_from_values,
)
from exporters.colours import (
    PALETTE,
    RGB,
    ATEBin,
    ate_bins,
    ate_edges_m,
    error_bins,
    error_unit,
    layer_name,
    palette_color,
    unique_layer_names,
)
from exporters.options import ExportOptions, Units
from loceval import __version__
from loceval.core.arrays import BoolArray, FloatArray, IntArray, StampsNs
from loceval.core.gaps import path_breaks
from loceval.core.geometry import SimilarityTransform
from loceval.core.polyline import simplify_rdp_runs
from loceval.evaluation import EstimateResult, EvaluationResult

_T = TypeVar("_T")

__all__ = [
    "BUILDING_SUFFIXES",
    "PALETTE",
    "RGB",
    "ATEBin",
    "ATERun",
    "ATERunArrays",
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

_NS_PER_S: Final = 1_000_000_000
_MARKER_MERGE_SHARE: Final = 0.05  # losses closer than 5 % of the drawing share a marker


class PathKind(StrEnum):
    """What a placed polyline shows."""

    REFERENCE = "reference"
    ESTIMATE = "estimate"


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
        rank: for ``"worst"``, its number ``#1`` ... ``#N`` (0 for a loss).
    """

    path: str
    kind: str
    position: tuple[float, float, float]
    target: tuple[float, float, float] | None
    label: str
    rank: int = 0


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
        crs: the projected CRS the site places the paths in (``"EPSG:25832"``), if known.
        building_bounds: (2, 3) [min, max] of the building model in model coordinates,
            output units, when one is given (legends are placed outside it).
    """

    result: EvaluationResult
    units: Units
    site: SimilarityTransform
    base_point_m: FloatArray
    simplify_m: float
    evaluation_id: str
    title: str
    paths: tuple[PlacedPath, ...]
    crs: str | None = None
    building_bounds: FloatArray | None = None
    _memo: dict[Hashable, object] = field(default_factory=dict, init=False, repr=False)

    def shared(self, key: Hashable, make: Callable[[], _T]) -> _T:
        """Return ``make()``, made once per placement and key.

        The CAD files of one run share the work this way: the ATE runs every format draws,
        the curves the .3dm and its JSON both carry. What it returns is shared: callers do
        not change it.
        """
        if key not in self._memo:
            self._memo[key] = make()
        return cast("_T", self._memo[key])

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
        """Return the ATE colour bins every output uses (:func:`error_bins`)."""
        return error_bins(self.result)

    def ate_runs(self, path: PlacedPath) -> list[ATERun]:
        """Return an estimate's path cut where its ATE changes bin, each run simplified.

        Runs never cross a break of the path (tracking loss); within one piece they join.
        The reference (no ATE) has none. Cut once per path of this placement.
        """
        if not any(p is path for p in self.paths):  # not one of ours: nothing to share
            return self._ate_run_arrays(path).runs()
        return list(self.shared(("ate_runs", id(path)), lambda: self.ate_run_arrays(path).runs()))

    def ate_run_arrays(self, path: PlacedPath) -> ATERunArrays:
        """Return :meth:`ate_runs` as flat arrays (what writers of many runs take), once."""
        if not any(p is path for p in self.paths):  # not one of ours: nothing to share
            return self._ate_run_arrays(path)
        return self.shared(("ate_run_arrays", id(path)), lambda: self._ate_run_arrays(path))

    def _ate_run_arrays(self, path: PlacedPath) -> ATERunArrays:
        est = path.estimate
        if est is None or len(est.aligned) == 0:
            return no_ate_runs(path.name)
        edges = np.array([b.high_m for b in self.ate_bins()[:-1]])
        return cut_ate_runs(
            path.name,
            self.to_model(est.aligned.positions_xyz),
            np.searchsorted(edges, est.ate_translation.values, side="left"),
            _jumps(self.result, est.aligned.stamps_ns),
            tolerance=self.simplify_m * self.units.per_metre,
            base_point=self.base_point,
        )

    def markers(self) -> list[Marker]:
        """Return one marker per tracking loss and one per greatest error, numbered by rank.

        A tracking loss of the reference is marked once (at its last pose before the
        loss), not once per trajectory; an estimate's own loss is marked where the
        reference kept tracking. Losses whose markers lie within 5 % of the drawing's size
        of each other share one, labelled by the longest (their labels would only pile
        up). Every greatest error is marked, ``#1`` ... ``#N`` by rank as the report and
        the viewer number them (the core lists distinct peaks, 2 s apart).
        """
        out = self._gap_markers()
        unit = error_unit(self.result)
        for path in self.paths:
            est = path.estimate
            if est is None:
                continue
            for rank, worst in enumerate(est.worst, start=1):  # a handful (--worst)
                here = self.to_model(est.aligned.positions_xyz[worst.index : worst.index + 1])
                there = self.to_model(np.array([worst.position_xyz]))
                out.append(
                    Marker(
                        path=path.name,
                        kind="worst",
                        position=_xyz(here[0]),
                        target=_xyz(there[0]),
                        label=(
                            f"{path.name} #{rank}: ATE {unit.text(worst.error)} "
                            f"at t={worst.t_s:.1f} s"
                        ),
                        rank=rank,
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
    layers = unique_layer_names([layer_name(n) for n in names])
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
        crs=options.crs,
        building_bounds=_building_bounds(options),
    )


def _building_bounds(options: ExportOptions) -> FloatArray | None:
    """Return the building's (2, 3) bounding box in model coordinates, output units, or None.

    Raises:
        ExportOptionsError: a building model that cannot be read.
    """
    if options.building is None:
        return None
    underlay = read_underlay(options.building, units=options.units, up=options.building_up)
    if isinstance(underlay, FloorPlan):
        ends = underlay.segments_m.reshape(-1, 2)
        points = np.column_stack([ends, np.zeros(len(ends))])
    else:
        points = underlay.vertices_m
    bounds = np.stack([points.min(axis=0), points.max(axis=0)])
    out: FloatArray = bounds * Units(options.units).per_metre
    return out


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
    if n == 0:
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp), 0.0
    # every piece simplified on its own, all in one work list (hundreds of tracking losses)
    bounds = np.concatenate(([0], np.flatnonzero(jump) + 1, [n])).astype(np.intp)
    keep, deviation = simplify_rdp_runs(model_m, bounds[:-1], bounds[1:], tolerance_m)
    kept: IntArray = np.flatnonzero(keep)
    return kept, np.searchsorted(kept, bounds[:-1]).astype(np.intp), deviation
