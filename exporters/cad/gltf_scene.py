"""What the GLB exporters share: the Z-up -> Y-up node matrix, colours, and the scene's buffer.

:mod:`exporters.cad.gltf` (an evaluation's trajectories) and :mod:`exporters.cad.gltf_points` (an
evaluation against control points) build their scenes on :class:`GlbScene`.
"""

from __future__ import annotations

from typing import Final

import numpy as np
import pygltflib
from numpy.typing import NDArray

from exporters.errors import ExportError
from loceval.core.arrays import FloatArray

__all__ = ["UNLIT", "Z_UP_TO_Y_UP", "GlbScene", "linear_rgba", "node_matrix"]

Z_UP_TO_Y_UP: Final = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
"""(3, 3) rotation -90° about X: REP 103 / CAD Z-up to glTF Y-up, (x, y, z) -> (x, z, -y)."""
UNLIT: Final = "KHR_materials_unlit"
"""The glTF extension of flat-coloured materials (lines and points have no normals)."""


def node_matrix(base_point_m: FloatArray) -> list[float]:
    """Return a node matrix (column-major, 16 numbers): Z-up -> Y-up, then the base point.

    Args:
        base_point_m: (3,) model coordinates (Z up, metres) of the local origin.
    """
    m = np.eye(4)
    m[:3, :3] = Z_UP_TO_Y_UP
    m[:3, 3] = Z_UP_TO_Y_UP @ np.asarray(base_point_m, dtype=np.float64)
    return [float(v) for v in m.T.reshape(-1)]  # glTF stores matrices column by column


def linear_rgba(rgb: tuple[int, int, int]) -> list[float]:
    """Convert 0-255 sRGB to linear RGBA (glTF's baseColorFactor is linear)."""
    c = np.asarray(rgb, dtype=np.float64) / 255.0
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return [*(round(float(v), 6) for v in linear), 1.0]


class GlbScene:
    """A glTF being built: its nodes, meshes, materials and one binary buffer.

    Attributes:
        matrix: the node matrix of every root node (:func:`node_matrix`).
        gltf: the glTF document.
        blob: the binary buffer.
        roots: the indices of the scene's root nodes.
    """

    def __init__(self, matrix: list[float]) -> None:
        """Start an empty scene whose root nodes get ``matrix``."""
        self.matrix = matrix
        self.gltf = pygltflib.GLTF2()
        self.blob = bytearray()
        self.roots: list[int] = []

    def view(self, data: bytes, target: int) -> int:
        """Append ``data`` to the buffer (4-byte aligned) as a buffer view; its index."""
        self.blob.extend(b"\0" * (-len(self.blob) % 4))  # 4-byte alignment of every view
        view = pygltflib.BufferView(
            buffer=0, byteOffset=len(self.blob), byteLength=len(data), target=target
        )
        self.blob.extend(data)
        self.gltf.bufferViews.append(view)
        return len(self.gltf.bufferViews) - 1

    def positions(self, positions: NDArray[np.float32]) -> int:
        """Add (N, 3) float32 positions as a VEC3 accessor with its bounds; its index."""
        view = self.view(positions.tobytes(), pygltflib.ARRAY_BUFFER)
        accessor = pygltflib.Accessor(
            bufferView=view,
            componentType=pygltflib.FLOAT,
            count=len(positions),
            type=pygltflib.VEC3,
            min=[float(v) for v in positions.min(axis=0)],  # the validator checks both
            max=[float(v) for v in positions.max(axis=0)],
        )
        self.gltf.accessors.append(accessor)
        return len(self.gltf.accessors) - 1

    def unlit_material(self, name: str, rgba: list[float]) -> int:
        """Add a flat-coloured (unlit) material of linear ``rgba``; its index."""
        self.gltf.materials.append(
            pygltflib.Material(
                name=name,
                pbrMetallicRoughness=pygltflib.PbrMetallicRoughness(
                    baseColorFactor=rgba, metallicFactor=0.0, roughnessFactor=1.0
                ),
                extensions={UNLIT: {}},
            )
        )
        return len(self.gltf.materials) - 1

    def to_glb(self, metadata: dict[str, object]) -> bytes:
        """Return the GLB of the finished scene (one scene, one buffer) with ``metadata``.

        Raises:
            ExportError: pygltflib could not serialize the scene.
        """
        gltf = self.gltf
        gltf.asset = pygltflib.Asset(version="2.0", generator=str(metadata["generator"]))
        gltf.extensionsUsed = [UNLIT]
        gltf.scenes = [
            pygltflib.Scene(name=str(metadata["title"]), nodes=list(self.roots), extras=metadata)
        ]
        gltf.scene = 0
        self.blob.extend(b"\0" * (-len(self.blob) % 4))
        gltf.buffers = [pygltflib.Buffer(byteLength=len(self.blob))]
        gltf.set_binary_blob(bytes(self.blob))
        try:
            return b"".join(gltf.save_to_bytes())
        except (ValueError, TypeError) as err:
            msg = f"pygltflib could not serialize the glTF scene ({err}); please report this."
            raise ExportError(msg) from err
