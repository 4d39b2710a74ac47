"""Arrays of 3D rotations held as unit quaternions ``x y z w``, in NumPy only.

:class:`Rotation` offers the part of ``scipy.spatial.transform.Rotation`` the core uses
(conversions to and from matrices, rotation vectors and fixed/moving-axis angles, applying,
composing, indexing, angles), with the same conventions and the same numbers. It exists for
start-up time: importing scipy's class loads ``scipy.spatial`` (KD-trees, ``scipy.sparse``,
Qhull) and scipy's array-API layer, 1.1 of the 1.9 billion instructions of starting the
command line (callgrind, ``python -c "import service.cli"``), while everything here is a
handful of vectorized NumPy expressions.

The formulas are the textbook ones: the rotation matrix of a unit quaternion, the
quaternion of a rotation matrix by the largest of the trace and the diagonal entries
(Shepperd 1978; Markley, "Unit Quaternion from Rotation Matrix", J. Guidance 31(2), 2008),
after projecting a non-orthogonal matrix onto the nearest rotation with an SVD (the
orthogonal Procrustes solution), and the exponential and logarithm maps with their Taylor
series near zero.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np

from loceval.core.arrays import FloatArray, IntArray
from loceval.core.norms import row_norms

__all__ = ["Rotation", "compose_quat", "conjugate_quat"]

_SMALL_ANGLE_RAD: Final = 1e-3
"""Below this angle the exp and log maps use their Taylor series (no 0/0)."""
_AXES: Final = {"x": 0, "y": 1, "z": 2}


def compose_quat(a_xyzw: FloatArray, b_xyzw: FloatArray) -> FloatArray:
    """Compose matching rows of two rotation arrays: ``a ∘ b`` (apply ``b`` first).

    The Hamilton product, vectorized; rows broadcast (one rotation against many).

    Args:
        a_xyzw: (N, 4) or (4,) unit quaternions x y z w.
        b_xyzw: (N, 4) or (4,) unit quaternions x y z w.

    Returns:
        (N, 4) (or (4,)) unit quaternions x y z w of the composed rotations.
    """
    x1, y1, z1, w1 = np.moveaxis(np.asarray(a_xyzw, dtype=np.float64), -1, 0)
    x2, y2, z2, w2 = np.moveaxis(np.asarray(b_xyzw, dtype=np.float64), -1, 0)
    out: FloatArray = np.stack(
        [
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        ],
        axis=-1,
    )
    return out


def conjugate_quat(quat_xyzw: FloatArray) -> FloatArray:
    """Return the inverse rotations of (N, 4) unit quaternions (the conjugates)."""
    out: FloatArray = np.asarray(quat_xyzw, dtype=np.float64) * np.array([-1.0, -1.0, -1.0, 1.0])
    return out


@dataclass(frozen=True, slots=True, eq=False)
class Rotation:
    """One rotation or an (N,) array of rotations, as unit quaternions ``x y z w``.

    Build it with the ``from_*`` class methods; a single input (a (4,) quaternion, a (3, 3)
    matrix, a (3,) rotation vector) gives a single rotation whose ``as_*`` results have no
    leading axis, as in scipy.

    Attributes:
        quat_xyzw: (N, 4) or (4,) float64 unit quaternions, read-only.
    """

    quat_xyzw: FloatArray

    def __post_init__(self) -> None:
        """Copy the quaternions, make them read-only and check their shape."""
        quat = np.array(self.quat_xyzw, dtype=np.float64)
        if quat.ndim not in {1, 2} or quat.shape[-1] != 4:
            msg = f"Quaternions must have shape (4,) or (N, 4), got {quat.shape!r}."
            raise ValueError(msg)
        quat.flags.writeable = False
        object.__setattr__(self, "quat_xyzw", quat)

    @property
    def single(self) -> bool:
        """Whether this is one rotation rather than an array of them."""
        return self.quat_xyzw.ndim == 1

    def __len__(self) -> int:
        """Return the number of rotations (a single rotation has no length)."""
        if self.single:
            msg = "A single rotation has no length."
            raise TypeError(msg)
        return int(self.quat_xyzw.shape[0])

    def __getitem__(self, index: int | slice | IntArray) -> Rotation:
        """Return the rotations at ``index`` (an int gives a single rotation)."""
        if self.single:
            msg = "A single rotation cannot be indexed."
            raise TypeError(msg)
        return Rotation(self.quat_xyzw[index])

    def __mul__(self, other: Rotation) -> Rotation:
        """Return ``self ∘ other`` (apply ``other`` first); one rotation broadcasts."""
        return Rotation(compose_quat(self.quat_xyzw, other.quat_xyzw))

    @classmethod
    def from_quat(cls, quat_xyzw: FloatArray) -> Rotation:
        """Return the rotations of quaternions ``x y z w``, normalized.

        Raises:
            ValueError: a quaternion has zero norm.
        """
        quat = np.asarray(quat_xyzw, dtype=np.float64)
        norm = row_norms(quat)[..., None]
        if np.any(norm == 0.0):
            msg = "A quaternion has zero norm and names no rotation."
            raise ValueError(msg)
        return cls(quat / norm)

    @classmethod
    def from_matrix(cls, matrix: FloatArray) -> Rotation:
        """Return the rotations of (3, 3) or (N, 3, 3) matrices.

        A matrix that is not orthogonal (printed with few digits) is replaced by the
        nearest rotation, ``U Vᵀ`` of its SVD, before the conversion.

        Raises:
            ValueError: a matrix has a non-positive determinant (a reflection or a
                degenerate frame).
        """
        m = np.array(matrix, dtype=np.float64)
        if m.shape[-2:] != (3, 3) or m.ndim not in {2, 3}:
            msg = f"Rotation matrices must have shape (3, 3) or (N, 3, 3), got {m.shape!r}."
            raise ValueError(msg)
        stacked = m.reshape(-1, 3, 3)
        det = np.linalg.det(stacked)
        if np.any(det <= 0.0):
            i = int(np.flatnonzero(det <= 0.0)[0])
            msg = f"Rotation matrix {i} has determinant {float(det[i])!r}; it is no rotation."
            raise ValueError(msg)
        gram = stacked @ stacked.transpose(0, 2, 1)
        skewed = ~np.isclose(gram, np.eye(3), rtol=1e-5, atol=1e-12).all(axis=(1, 2))
        if skewed.any():
            u, _, vt = np.linalg.svd(stacked[skewed])
            stacked[skewed] = u @ vt
        quat = _quat_from_orthogonal(stacked)
        return cls(quat[0] if m.ndim == 2 else quat)

    @classmethod
    def from_rotvec(cls, rotvec: FloatArray) -> Rotation:
        """Return the rotations of (3,) or (N, 3) rotation vectors (axis times angle, rad)."""
        v = np.asarray(rotvec, dtype=np.float64)
        angle = row_norms(v)[..., None]
        small = angle <= _SMALL_ANGLE_RAD
        angle2 = angle * angle
        # sin(a/2)/a, with its series 1/2 - a²/48 + a⁴/3840 near zero.
        scale = np.where(
            small,
            0.5 - angle2 / 48.0 + angle2 * angle2 / 3840.0,
            np.sin(angle / 2.0) / np.where(small, 1.0, angle),
        )
        return cls(np.concatenate([v * scale, np.cos(angle / 2.0)], axis=-1))

    @classmethod
    def from_euler(cls, seq: str, angles: FloatArray, *, degrees: bool = False) -> Rotation:
        """Return the rotations of successive turns about coordinate axes.

        Args:
            seq: up to three axes, lower case for fixed axes (extrinsic: ``"xyz"`` is
                ``Rz Ry Rx``, URDF's roll-pitch-yaw) or upper case for moving axes
                (intrinsic: ``"ZYX"`` is ``Rz Ry Rx`` as well).
            angles: (len(seq),) or (N, len(seq)) angles; a scalar for one axis.
            degrees: whether the angles are in degrees (else radians).

        Raises:
            ValueError: the sequence mixes cases, names another axis, or does not match
                the angles.
        """
        intrinsic = seq.isupper()
        if not (1 <= len(seq) <= 3) or not (intrinsic or seq.islower()):
            msg = f"Axis sequence {seq!r} must be 1 to 3 of x, y, z, all lower or all upper."
            raise ValueError(msg)
        a = np.asarray(angles, dtype=np.float64)
        single = a.ndim == 0 or (a.ndim == 1 and len(seq) > 1)
        a = a.reshape(-1, len(seq))
        if degrees:
            a = np.radians(a)
        quat = np.zeros((a.shape[0], 4))
        quat[:, 3] = 1.0
        for k, axis in enumerate(seq.lower()):  # one turn per axis, vectorized over rows
            if axis not in _AXES:
                msg = f"Axis sequence {seq!r} names {axis!r}; use x, y and z."
                raise ValueError(msg)
            turn = np.zeros_like(quat)
            turn[:, _AXES[axis]] = np.sin(a[:, k] / 2.0)
            turn[:, 3] = np.cos(a[:, k] / 2.0)
            quat = compose_quat(quat, turn) if intrinsic else compose_quat(turn, quat)
        return cls(quat[0] if single else quat)

    def as_quat(self) -> FloatArray:
        """Return (N, 4) or (4,) quaternions ``x y z w`` (a copy, sign as stored)."""
        out: FloatArray = self.quat_xyzw.copy()
        return out

    def as_matrix(self) -> FloatArray:
        """Return (N, 3, 3) or (3, 3) rotation matrices."""
        x, y, z, w = np.moveaxis(self.quat_xyzw, -1, 0)
        x2, y2, z2, w2 = x * x, y * y, z * z, w * w
        xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
        rows = [
            [x2 - y2 - z2 + w2, 2.0 * (xy - zw), 2.0 * (xz + yw)],
            [2.0 * (xy + zw), -x2 + y2 - z2 + w2, 2.0 * (yz - xw)],
            [2.0 * (xz - yw), 2.0 * (yz + xw), -x2 - y2 + z2 + w2],
        ]
        out: FloatArray = np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)
        return out

    def as_rotvec(self) -> FloatArray:
        """Return (N, 3) or (3,) rotation vectors (axis times angle in [0, π], rad)."""
        quat = _canonical(self.quat_xyzw)
        sin_half = row_norms(quat[..., :3])[..., None]
        angle = 2.0 * np.arctan2(sin_half, quat[..., 3:])
        small = angle <= _SMALL_ANGLE_RAD
        angle2 = angle * angle
        # a / sin(a/2), with its series 2 + a²/12 + 7a⁴/2880 near zero.
        scale = np.where(
            small,
            2.0 + angle2 / 12.0 + 7.0 * angle2 * angle2 / 2880.0,
            angle / np.where(small, 1.0, np.sin(angle / 2.0)),
        )
        out: FloatArray = scale * quat[..., :3]
        return out

    def magnitude(self) -> FloatArray:
        """Return the rotation angles in [0, π] rad, (N,) (a 0-d array for one rotation)."""
        sin_half = row_norms(self.quat_xyzw[..., :3])
        out: FloatArray = 2.0 * np.arctan2(sin_half, np.abs(self.quat_xyzw[..., 3]))
        return out

    def inv(self) -> Rotation:
        """Return the inverse rotations."""
        return Rotation(conjugate_quat(self.quat_xyzw))

    def apply(self, vectors: FloatArray, *, inverse: bool = False) -> FloatArray:
        """Rotate (N, 3) or (3,) vectors; one rotation or one vector broadcasts.

        Args:
            vectors: the vectors.
            inverse: apply the inverse rotations instead.

        Returns:
            The rotated vectors, (N, 3) (or (3,) for one rotation and one vector).
        """
        matrix = self.as_matrix()
        if inverse:
            matrix = np.swapaxes(matrix, -1, -2)
        out: FloatArray = (matrix @ np.asarray(vectors, dtype=np.float64)[..., None])[..., 0]
        return out


def _canonical(quat_xyzw: FloatArray) -> FloatArray:
    """Flip each quaternion to w > 0 (ties broken by x, then y, then z): one per rotation."""
    x, y, z, w = np.moveaxis(quat_xyzw, -1, 0)
    flip = (w < 0) | ((w == 0) & ((x < 0) | ((x == 0) & ((y < 0) | ((y == 0) & (z < 0))))))
    out: FloatArray = np.where(flip[..., None], -quat_xyzw, quat_xyzw)
    return out


def _quat_from_orthogonal(m: FloatArray) -> FloatArray:
    """Return (N, 4) unit quaternions of (N, 3, 3) rotation matrices.

    Each quaternion is built from the largest of ``m00, m11, m22, trace`` so that the
    component divided through is never small (Shepperd's method, Markley eq. 14-18).
    """
    trace = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    choice = np.argmax(np.stack([m[:, 0, 0], m[:, 1, 1], m[:, 2, 2], trace], axis=1), axis=1)
    candidates = np.stack(
        [
            [
                1.0 - trace + 2.0 * m[:, 0, 0],
                m[:, 1, 0] + m[:, 0, 1],
                m[:, 2, 0] + m[:, 0, 2],
                m[:, 2, 1] - m[:, 1, 2],
            ],
            [
                m[:, 1, 0] + m[:, 0, 1],
                1.0 - trace + 2.0 * m[:, 1, 1],
                m[:, 2, 1] + m[:, 1, 2],
                m[:, 0, 2] - m[:, 2, 0],
            ],
            [
                m[:, 2, 0] + m[:, 0, 2],
                m[:, 2, 1] + m[:, 1, 2],
                1.0 - trace + 2.0 * m[:, 2, 2],
                m[:, 1, 0] - m[:, 0, 1],
            ],
            [
                m[:, 2, 1] - m[:, 1, 2],
                m[:, 0, 2] - m[:, 2, 0],
                m[:, 1, 0] - m[:, 0, 1],
                1.0 + trace,
            ],
        ]
    )  # (case, component, N)
    quat = candidates[choice, :, np.arange(m.shape[0])]
    out: FloatArray = quat / row_norms(quat)[:, None]
    return out
