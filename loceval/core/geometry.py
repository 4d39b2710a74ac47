"""Rigid and similarity transforms, and vectorized rotation helpers.

Quaternions are ``x y z w`` (scipy's order, ROS messages, TUM files) everywhere in here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from loceval.core.arrays import FloatArray
from loceval.core.rotation import Rotation, compose_quat, conjugate_quat
from loceval.errors import InputError

__all__ = [
    "SimilarityTransform",
    "compose_quat",
    "conjugate_quat",
    "relative_angle_deg",
    "skew",
    "slerp_pairs",
]


@dataclass(frozen=True, slots=True, eq=False)
class SimilarityTransform:
    """``x -> scale * R @ x + t``: maps points of one frame into another.

    Attributes:
        rotation: (3, 3) rotation matrix R.
        translation: (3,) translation t in metres.
        scale: positive scale s (1.0 for rigid transforms).
    """

    rotation: FloatArray
    translation: FloatArray
    scale: float = 1.0

    def __post_init__(self) -> None:
        """Copy the arrays, make them read-only and check them."""
        rotation = np.array(self.rotation, dtype=np.float64)
        translation = np.array(self.translation, dtype=np.float64).reshape(-1)
        if rotation.shape != (3, 3) or translation.shape != (3,):
            msg = (
                f"A transform needs a (3, 3) rotation and a (3,) translation, "
                f"got {rotation.shape!r} and {translation.shape!r}."
            )
            raise InputError(msg)
        if not (np.isfinite(rotation).all() and np.isfinite(translation).all()):
            msg = "A transform must be finite; got NaN or inf."
            raise InputError(msg)
        if not (np.isfinite(self.scale) and self.scale > 0.0):
            msg = f"A transform's scale must be positive and finite, got {self.scale!r}."
            raise InputError(msg)
        rotation.flags.writeable = False
        translation.flags.writeable = False
        object.__setattr__(self, "rotation", rotation)
        object.__setattr__(self, "translation", translation)
        object.__setattr__(self, "scale", float(self.scale))

    @classmethod
    def identity(cls) -> SimilarityTransform:
        """Return the identity transform."""
        return cls(np.eye(3), np.zeros(3), 1.0)

    @classmethod
    def from_pose(cls, position_xyz: FloatArray, quat_xyzw: FloatArray) -> SimilarityTransform:
        """Return the rigid transform of a pose (body frame -> world frame).

        Args:
            position_xyz: (3,) position in metres.
            quat_xyzw: (4,) unit quaternion x y z w.
        """
        return cls(Rotation.from_quat(quat_xyzw).as_matrix(), position_xyz, 1.0)

    @classmethod
    def from_matrix(cls, matrix: FloatArray) -> SimilarityTransform:
        """Return the transform of a (4, 4) homogeneous matrix ``[[sR, t], [0, 1]]``.

        Raises:
            InputError: the matrix is not a similarity transform.
        """
        m = np.asarray(matrix, dtype=np.float64)
        if m.shape != (4, 4) or not np.allclose(m[3], [0.0, 0.0, 0.0, 1.0]):
            msg = "A transform matrix must be 4x4 with a last row of 0 0 0 1."
            raise InputError(msg)
        sr = m[:3, :3]
        det = float(np.linalg.det(sr))
        if det <= 0.0:
            msg = f"A transform matrix must have a positive determinant, got {det!r}."
            raise InputError(msg)
        scale = det ** (1.0 / 3.0)
        rotation = sr / scale
        if not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-6):
            msg = "A transform matrix's upper 3x3 block is not a scaled rotation."
            raise InputError(msg)
        return cls(rotation, m[:3, 3], scale)

    @property
    def is_rigid(self) -> bool:
        """Whether the scale is 1."""
        return bool(np.isclose(self.scale, 1.0, rtol=0.0, atol=1e-12))

    def as_matrix(self) -> FloatArray:
        """Return the (4, 4) homogeneous matrix ``[[sR, t], [0, 1]]``."""
        m = np.eye(4)
        m[:3, :3] = self.scale * self.rotation
        m[:3, 3] = self.translation
        return m

    def inverse(self) -> SimilarityTransform:
        """Return the transform that undoes this one."""
        rotation_inv = self.rotation.T
        scale_inv = 1.0 / self.scale
        return SimilarityTransform(
            rotation_inv, -scale_inv * (rotation_inv @ self.translation), scale_inv
        )

    def compose(self, other: SimilarityTransform) -> SimilarityTransform:
        """Return ``self ∘ other`` (apply ``other`` first)."""
        return SimilarityTransform(
            self.rotation @ other.rotation,
            self.scale * (self.rotation @ other.translation) + self.translation,
            self.scale * other.scale,
        )

    def apply_positions(self, positions_xyz: FloatArray) -> FloatArray:
        """Map (N, 3) positions; returns a new (N, 3) array."""
        out: FloatArray = self.scale * (positions_xyz @ self.rotation.T) + self.translation
        return out

    def apply_orientations(self, quat_xyzw: FloatArray) -> FloatArray:
        """Rotate (N, 4) orientations by R (the scale does not act on rotations)."""
        q_rot = Rotation.from_matrix(self.rotation).as_quat()
        return compose_quat(np.broadcast_to(q_rot, quat_xyzw.shape), quat_xyzw)

    def to_dict(self) -> dict[str, object]:
        """Return ``{"rotation": 3x3 list, "translation": [x, y, z], "scale": s}``."""
        return {
            "rotation": self.rotation.tolist(),
            "translation": self.translation.tolist(),
            "scale": self.scale,
        }


def slerp_pairs(q0_xyzw: FloatArray, q1_xyzw: FloatArray, weights: FloatArray) -> FloatArray:
    """Spherical linear interpolation between matching rows of two quaternion arrays.

    ``q0 ∘ exp(w · log(q0^-1 ∘ q1))``, with rotation vectors for log and exp.

    Args:
        q0_xyzw: (N, 4) start orientations.
        q1_xyzw: (N, 4) end orientations.
        weights: (N,) interpolation weights in [0, 1] (0 gives ``q0``).

    Returns:
        (N, 4) interpolated unit quaternions x y z w, along the shorter arc.
    """
    delta = Rotation.from_quat(compose_quat(conjugate_quat(q0_xyzw), q1_xyzw)).as_rotvec()
    step = Rotation.from_rotvec(delta * weights[:, None]).as_quat()
    return compose_quat(q0_xyzw, step)


def relative_angle_deg(q_a_xyzw: FloatArray, q_b_xyzw: FloatArray) -> FloatArray:
    """Angle (degrees) of the rotation between matching rows of two orientation arrays.

    Args:
        q_a_xyzw: (N, 4) orientations.
        q_b_xyzw: (N, 4) orientations.

    Returns:
        (N,) angles in [0, 180] degrees.
    """
    delta = Rotation.from_quat(compose_quat(conjugate_quat(q_a_xyzw), q_b_xyzw))
    out: FloatArray = np.degrees(delta.magnitude())
    return out


def skew(v: FloatArray) -> FloatArray:
    """Return the (N, 3, 3) cross-product matrices ``[v]×`` of (N, 3) vectors."""
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out
