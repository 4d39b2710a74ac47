"""glTF 2.0 binary (GLB) export: a node per trajectory, its ATE colours, markers; indexed LINES.

Nodes, named from the trajectories (the scene from the evaluation's title):

- ``<name>``: the path in its palette colour, one ``LINES`` primitive per continuous
  piece (a path breaks at tracking loss instead of crossing it with a chord);
- ``<name> ATE`` (estimates): the path in the report's ATE colours as vertex colours
  (``COLOR_0``, linear RGB; colour runs of one piece share a duplicated joint vertex, so
  the colour changes sharply, not in a blend);
- ``<name> markers`` (estimates) and ``tracking loss``: empty nodes whose children sit at the
  greatest errors and at each tracking loss, named by their labels;
- ``map walls`` (with a measured map): the wall cells as points coloured by their distance
  to the plan; ``excursions``: one purple ``LINES`` primitive per stretch outside the tracked
  room (:mod:`exporters.cad.excursions`), its label and figures in the node's extras.

Conventions (glTF 2.0 §3.4): distances are metres and +Y is up, whatever the CAD units say
(the DXF and 3DM files follow the units; glTF importers such as Rhino's and Blender's
expect metres and convert to the document's units themselves). Each node's matrix is

    M = [[R, R @ b], [0, 1]],   R: (x, y, z) -> (x, z, -y)   (-90° about X, Z-up -> Y-up)

with ``b`` the base point (the reference's bounding-box centre in model coordinates, rounded
to whole metres).
Positions are float32 and local (model metres minus ``b``), so a path 500 km from the
model origin keeps millimetre precision; the offset lives in the node matrix, written in
full double precision in the JSON. Primitives are ``LINES`` (mode 1) indexed as a polyline
(0 1, 1 2, ...), not ``LINE_STRIP`` (mode 3): trimesh, the mission's mesh library, skips
strips and loads indexed lines as one Path3D polyline per piece; three.js' GLTFLoader
draws them as LineSegments; the Khronos validator accepts both (issue 44).

A building model (OBJ, PLY, STL, GLB or IFC, read by :func:`exporters.cad.building.read_building`)
joins the same scene as a ``TRIANGLES`` mesh. OBJ, PLY and STL are taken to be in model
coordinates, in the output units, Z up (as CAD programs export them; ``building_up="y"``
for Y-up exports); a GLB building is taken to follow glTF (metres, Y up) in model
coordinates; an IFC gives its own units and, with a map conversion, map coordinates.
Either way it gets the same base point and Z-up -> Y-up matrix.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Final

import numpy as np
import pygltflib
from numpy.typing import NDArray

from exporters.cad.building import read_building
from exporters.cad.excursions import EXCURSION_LAYER, EXCURSION_RGB, placed_excursions
from exporters.cad.gltf_scene import Z_UP_TO_Y_UP, GlbScene, linear_rgba, node_matrix
from exporters.cad.placement import ATERunArrays, Marker, Placement, place_evaluation
from exporters.colours import map_bins, scale_words
from exporters.options import ExportOptions
from loceval.core.arrays import FloatArray
from loceval.evaluation import EvaluationResult

__all__ = ["Z_UP_TO_Y_UP", "export_glb", "node_matrix"]

_BUILDING_RGBA: Final = (0.75, 0.75, 0.75, 0.35)
_CLUTTER_RGB: Final = (194, 24, 91)


def export_glb(
    result: EvaluationResult, options: ExportOptions, *, placement: Placement | None = None
) -> bytes:
    """Write the evaluation's trajectories (and the building, if given) as a GLB.

    Args:
        result: the evaluation.
        options: site transform, simplification, ids, and the optional building mesh.
        placement: the placed paths, when the caller computed them for several formats.

    Returns:
        The GLB file.

    Raises:
        ExportOptionsError: unusable placement options, or a building file that is
            missing, unreadable or of an unsupported format.
        ExportError: pygltflib could not serialize the scene.
    """
    placement = placement or place_evaluation(result, options)
    scene = _SceneBuilder(node_matrix(placement.base_point_m))
    per_metre = placement.units.per_metre
    ate_nodes = []
    bins = placement.ate_bins()
    bin_rgb = np.array([linear_rgba(b.color_rgb)[:3] for b in bins], dtype=np.float32)
    for path in placement.paths:
        pieces = [
            (path.local_vertices[a:b] / per_metre).astype(np.float32)
            for a, b in path.pieces()
            if b - a >= 2
        ]
        extras = {**path.metadata(), "units": "m", "output_units": placement.units.value}
        scene.add_lines(path.name, pieces, linear_rgba(path.color_rgb), extras)
        runs = placement.ate_run_arrays(path)
        if len(runs):
            ate_nodes.append((path, runs))
    for path, runs in ate_nodes:
        strips, colours = _ate_strips(runs, bin_rgb, per_metre)
        extras = {
            "kind": "ate",
            "path": path.name,
            "legend": scale_words(result),
            "ate_bins": [
                {"label": b.label, "color": list(b.color_rgb), "beyond": b.beyond} for b in bins
            ],
        }
        scene.add_lines(f"{path.name} ATE", strips, [1.0, 1.0, 1.0, 1.0], extras, colours)
    markers = placement.markers()
    for path in placement.paths:
        worst = [m for m in markers if m.kind == "worst" and m.path == path.name]
        scene.add_markers(f"{path.name} markers", worst, placement.base_point, per_metre)
    losses = [m for m in markers if m.kind == "gap"]
    scene.add_markers("tracking loss", losses, placement.base_point, per_metre)
    _add_map(scene, placement)
    _add_excursions(scene, placement)
    plan_only = options.building is not None and options.building.suffix.lower() == ".dxf"
    if options.building is not None and not plan_only:
        building = read_building(options.building, units=placement.units, up=options.building_up)
        local_m = (building.vertices_m - placement.base_point_m).astype(np.float32)
        scene.add_building(options.building, local_m, building.faces.astype(np.uint32))
    meta = placement.metadata()
    meta.update(
        units="m",
        output_units=placement.units.value,
        base_point=placement.base_point_m.tolist(),
        gltf_convention="metres, Y up; node matrix = base point ∘ (Z-up -> Y-up)",
    )
    if plan_only and options.building is not None:  # a 2D drawing has no mesh for the scene
        meta["building_note"] = f"{options.building.name} is a 2D floor plan, not in the scene"
    return scene.to_glb(meta)


def _add_map(scene: _SceneBuilder, placement: Placement) -> None:
    """Add ``map walls``: every wall cell a point coloured by its distance (with a map)."""
    found = placement.result.map
    if found is None:
        return
    z = float(np.median(placement.result.reference.positions_xyz[:, 2]))
    xyz = placement.to_model(np.column_stack([found.cells_xy, np.full(len(found.cells_xy), z)]))
    local = ((xyz - placement.base_point) / placement.units.per_metre).astype(np.float32)
    bins = map_bins(found.distance_m, placement.result.config.thresholds_m)
    palette = np.array(
        [linear_rgba(rgb)[:3] for rgb in (*(b.color_rgb for b in bins), _CLUTTER_RGB)],
        dtype=np.float32,
    )
    index = np.searchsorted([b.high_m for b in bins[:-1]], found.distance_m, side="left")
    index[found.clutter] = len(bins)
    extras: dict[str, object] = {
        "kind": "map",
        "bins": [{"label": b.label, "color": list(b.color_rgb)} for b in bins],
        "clutter_color": list(_CLUTTER_RGB),
    }
    scene.add_points("map walls", local, palette[index], extras)


def _add_excursions(scene: _SceneBuilder, placement: Placement) -> None:
    """Add ``excursions``: a purple polyline per path outside the tracked room, labelled."""
    placed = placed_excursions(placement)
    if not placed:
        return
    per_metre = placement.units.per_metre
    strips = [((v - placement.base_point) / per_metre).astype(np.float32) for _, v in placed]
    extras: dict[str, object] = {
        "kind": "excursions",
        "excursions": [  # in the order of the node's primitives
            {"label": p.label, "estimate": p.estimate, **p.figures} for p, _ in placed
        ],
    }
    scene.add_lines(EXCURSION_LAYER, strips, linear_rgba(EXCURSION_RGB), extras)


def _ate_strips(
    runs: ATERunArrays, bin_rgb: NDArray[np.float32], per_metre: float
) -> tuple[list[NDArray[np.float32]], list[NDArray[np.float32]]]:
    """Join an estimate's ATE runs into one strip per piece, with a colour per vertex.

    The runs of a piece lie one after another in ``runs``' vertices (each with its joining
    vertex), so a strip is one slice of them; its colours, each run's bin colour repeated.
    """
    bounds = runs.offsets[np.flatnonzero(np.diff(runs.piece, prepend=-1, append=-1))]
    local = (runs.local_vertices / per_metre).astype(np.float32)
    colours = np.repeat(bin_rgb[runs.bin_index], np.diff(runs.offsets), axis=0)
    pairs = list(itertools.pairwise(bounds.tolist()))  # one per piece (tracking losses)
    return [local[a:b] for a, b in pairs], [colours[a:b] for a, b in pairs]


class _SceneBuilder(GlbScene):
    """Collects nodes, meshes, materials and one binary buffer."""

    def _colours(self, colours: NDArray[np.float32]) -> int:
        view = self.view(colours.tobytes(), pygltflib.ARRAY_BUFFER)
        accessor = pygltflib.Accessor(
            bufferView=view, componentType=pygltflib.FLOAT, count=len(colours), type=pygltflib.VEC3
        )
        self.gltf.accessors.append(accessor)
        return len(self.gltf.accessors) - 1

    def _segments(self, count: int) -> int:
        """Add the indices of a polyline of ``count`` vertices as LINES (0 1, 1 2, ...)."""
        pairs = np.repeat(np.arange(count, dtype=np.uint32), 2)[1:-1]
        view = self.view(pairs.tobytes(), pygltflib.ELEMENT_ARRAY_BUFFER)
        accessor = pygltflib.Accessor(
            bufferView=view,
            componentType=pygltflib.UNSIGNED_INT,
            count=len(pairs),
            type=pygltflib.SCALAR,
            min=[int(pairs.min())],
            max=[int(pairs.max())],
        )
        self.gltf.accessors.append(accessor)
        return len(self.gltf.accessors) - 1

    def _node(self, name: str, mesh: pygltflib.Mesh, extras: dict[str, object]) -> None:
        self.gltf.meshes.append(mesh)
        self.gltf.nodes.append(
            pygltflib.Node(
                name=name, mesh=len(self.gltf.meshes) - 1, matrix=self.matrix, extras=extras
            )
        )
        self.roots.append(len(self.gltf.nodes) - 1)

    def add_lines(
        self,
        name: str,
        pieces: list[NDArray[np.float32]],
        rgba: list[float],
        extras: dict[str, object],
        colours: list[NDArray[np.float32]] | None = None,
    ) -> None:
        """Add a path: an indexed LINES polyline per piece (vertex colours if given), node."""
        material = self.unlit_material(name, rgba)
        primitives = []
        for k, positions in enumerate(pieces):  # one primitive per continuous piece
            attributes = pygltflib.Attributes(POSITION=self.positions(positions))
            if colours is not None:
                attributes.COLOR_0 = self._colours(colours[k])
            primitives.append(
                pygltflib.Primitive(
                    attributes=attributes,
                    indices=self._segments(len(positions)),
                    material=material,
                    mode=pygltflib.LINES,
                )
            )
        self._node(name, pygltflib.Mesh(name=name, primitives=primitives), extras)

    def add_points(
        self,
        name: str,
        positions: NDArray[np.float32],
        colours: NDArray[np.float32],
        extras: dict[str, object],
    ) -> None:
        """Add one POINTS primitive with a colour per point, and its node."""
        material = self.unlit_material(name, [1.0, 1.0, 1.0, 1.0])
        attributes = pygltflib.Attributes(POSITION=self.positions(positions))
        attributes.COLOR_0 = self._colours(np.ascontiguousarray(colours))
        primitive = pygltflib.Primitive(
            attributes=attributes, material=material, mode=pygltflib.POINTS
        )
        self._node(name, pygltflib.Mesh(name=name, primitives=[primitive]), extras)

    def add_markers(
        self, name: str, markers: list[Marker], base_point: FloatArray, per_metre: float
    ) -> None:
        """Add an empty node ``name`` whose children stand at the markers, named by labels."""
        if not markers:
            return
        children = []
        for marker in markers:  # a few dozen at most
            local_m = (np.asarray(marker.position) - base_point) / per_metre
            self.gltf.nodes.append(
                pygltflib.Node(
                    name=marker.label,
                    translation=[float(v) for v in local_m],
                    extras={"kind": marker.kind, "path": marker.path, "label": marker.label},
                )
            )
            children.append(len(self.gltf.nodes) - 1)
        self.gltf.nodes.append(
            pygltflib.Node(
                name=name, matrix=self.matrix, children=children, extras={"kind": "markers"}
            )
        )
        self.roots.append(len(self.gltf.nodes) - 1)

    def add_building(
        self, source: Path, positions: NDArray[np.float32], faces: NDArray[np.uint32]
    ) -> None:
        """Add the building: TRIANGLES mesh with a translucent grey material."""
        self.gltf.materials.append(
            pygltflib.Material(
                name="building",
                pbrMetallicRoughness=pygltflib.PbrMetallicRoughness(
                    baseColorFactor=list(_BUILDING_RGBA), metallicFactor=0.0, roughnessFactor=0.9
                ),
                alphaMode=pygltflib.BLEND,
                doubleSided=True,
            )
        )
        indices = self.view(faces.reshape(-1).tobytes(), pygltflib.ELEMENT_ARRAY_BUFFER)
        self.gltf.accessors.append(
            pygltflib.Accessor(
                bufferView=indices,
                componentType=pygltflib.UNSIGNED_INT,
                count=int(faces.size),
                type=pygltflib.SCALAR,
            )
        )
        index_accessor = len(self.gltf.accessors) - 1
        primitive = pygltflib.Primitive(
            attributes=pygltflib.Attributes(POSITION=self.positions(positions)),
            indices=index_accessor,
            material=len(self.gltf.materials) - 1,
            mode=pygltflib.TRIANGLES,
        )
        extras: dict[str, object] = {"kind": "building", "source": source.name}
        self._node("building", pygltflib.Mesh(name="building", primitives=[primitive]), extras)
