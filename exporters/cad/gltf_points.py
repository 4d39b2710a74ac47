"""GLB of an evaluation against control points (written as ``paths.glb``).

The same content as the DXF (:mod:`exporters.cad.dxf_points`), a root node per layer:

- ``control points``: the surveyed points as one ``POINTS`` primitive, with a child node
  per point at its position, named by its id;
- ``<estimate> measured``: the measured (aligned median) positions as ``POINTS``;
- ``<estimate> errors``: a ``LINES`` segment from the surveyed point to the measured position
  per visit (visits that fixed the alignment in a grey primitive of their own), with a
  child node per visit at the measured position, named by its label (``P01 12.3 mm``).

Conventions as :mod:`exporters.cad.gltf`: metres and +Y up, float32 positions relative to the
base point (the points' bounding-box centre in model metres, rounded to whole metres),
which lives with the Z-up -> Y-up rotation in each root node's matrix
(:func:`exporters.cad.gltf.node_matrix`).
"""

from __future__ import annotations

import numpy as np
import pygltflib
from numpy.typing import NDArray

from exporters.cad.gltf_scene import GlbScene, linear_rgba, node_matrix
from exporters.cad.points_placement import (
    ALIGNMENT_RGB,
    POINTS_LAYER,
    POINTS_RGB,
    PlacedControlPoints,
    place_control_points,
)
from exporters.colours import RGB
from exporters.options import ExportOptions
from loceval.checkpoint_evaluation import CheckpointEvaluation
from loceval.core.arrays import FloatArray

__all__ = ["export_points_glb"]


def export_points_glb(evaluation: CheckpointEvaluation, options: ExportOptions) -> bytes:
    """Write the control points, measured positions and error lines as a GLB.

    Raises:
        ExportError: pygltflib could not serialize the scene.
    """
    placed = place_control_points(evaluation, options)
    scene = _Scene(placed)
    scene.add(POINTS_LAYER, pygltflib.POINTS, [(placed.points, POINTS_RGB)], placed.ids)
    for est in placed.estimates:
        if not len(est.measured):
            continue
        scene.add(est.measured_layer, pygltflib.POINTS, [(est.measured, est.color_rgb)], ())
        # LINES: surveyed, measured, surveyed, measured, ... (a pair per visit)
        pairs = np.stack([est.surveyed, est.measured], axis=1).reshape(-1, 3)
        flags = np.repeat(est.alignment, 2)
        groups = [(pairs[~flags], est.color_rgb), (pairs[flags], ALIGNMENT_RGB)]
        scene.add(
            est.errors_layer,
            pygltflib.LINES,
            [(p, rgb) for p, rgb in groups if len(p)],
            est.labels,
            at=est.measured,
        )
    metadata = {
        **placed.metadata,
        "units": "m",
        "output_units": placed.units.value,
        "base_point": placed.base_point_m.tolist(),
        "gltf_convention": "metres, Y up; node matrix = base point ∘ (Z-up -> Y-up)",
    }
    return scene.to_glb(metadata)


class _Scene(GlbScene):
    """Collects the nodes, meshes, materials and the binary buffer of the GLB."""

    def __init__(self, placed: PlacedControlPoints) -> None:
        super().__init__(node_matrix(placed.base_point_m))
        self.per_metre = placed.units.per_metre
        self.base_m = placed.base_point_m

    def _local(self, model: FloatArray) -> NDArray[np.float32]:
        """Model coordinates (output units) -> float32 metres relative to the base point."""
        return (model / self.per_metre - self.base_m).astype(np.float32)

    def add(
        self,
        name: str,
        mode: int,
        groups: list[tuple[FloatArray, RGB]],
        labels: tuple[str, ...],
        *,
        at: FloatArray | None = None,
    ) -> None:
        """Add a root node ``name``: a primitive per (positions, colour) group, labels.

        ``labels`` name the children placed at ``at`` (default: the first group's points).
        """
        primitives = [
            pygltflib.Primitive(
                attributes=pygltflib.Attributes(POSITION=self.positions(self._local(model))),
                material=self.unlit_material(f"{name} {k}" if k else name, linear_rgba(rgb)),
                mode=mode,
            )
            for k, (model, rgb) in enumerate(groups)
        ]
        self.gltf.meshes.append(pygltflib.Mesh(name=name, primitives=primitives))
        children = []
        anchors = self._local(groups[0][0] if at is None else at) if labels else np.empty((0, 3))
        for label, local in zip(labels, anchors.astype(np.float64).tolist(), strict=True):
            self.gltf.nodes.append(pygltflib.Node(name=label, translation=local))
            children.append(len(self.gltf.nodes) - 1)
        kind = "points" if mode == pygltflib.POINTS else "lines"
        self.gltf.nodes.append(
            pygltflib.Node(
                name=name,
                mesh=len(self.gltf.meshes) - 1,
                matrix=self.matrix,
                children=children,
                extras={"kind": kind, "layer": name, "labels": list(labels)},
            )
        )
        self.roots.append(len(self.gltf.nodes) - 1)
