"""The trajectory value type: stamped positions with optional orientations."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from loceval.core.arrays import BoolArray, FloatArray, IntArray, StampsNs
from loceval.core.display import display_text
from loceval.core.gaps import tracking_losses
from loceval.core.geometry import SimilarityTransform, skew
from loceval.core.norms import row_norms
from loceval.core.quantiles import median
from loceval.core.quantities import format_duration
from loceval.core.rotation import Rotation
from loceval.errors import TrajectoryError

NO_TIMES = "no timestamps (poses numbered)"
"""What a trajectory without times spans (a KITTI file without its times file)."""

__all__ = ["MAX_COORDINATE_M", "MAX_OFFSET_M", "MAX_SPAN_S", "MIN_POSES", "Trajectory"]

MIN_POSES = 3
"""Fewest poses a trajectory may have: alignment and RPE need at least three."""
MAX_COORDINATE_M = 1e9
"""Largest position magnitude accepted: beyond any site (ECEF is 6.4e6 m); not metres."""
MAX_OFFSET_M = 1e3
"""Largest lever arm on one device (a rigid body to its sensor, a tag), metres."""
MAX_SPAN_S = 1e9
"""Longest time span (about 32 years) an option may name: stamps are int64 ns (±292 years),
so a longer span overflows them and can only be a typo."""

_NS_PER_S = 1_000_000_000


@dataclass(frozen=True, slots=True, eq=False)
class Trajectory:
    """An immutable stamped trajectory.

    The arrays are copied and made read-only on construction; every operation returns a
    new trajectory. Stamps are strictly increasing (readers sort and de-duplicate).

    Attributes:
        stamps_ns: (N,) int64 nanoseconds, strictly increasing.
        positions_xyz: (N, 3) float64 metres, REP 103 (x forward, y left, z up).
        quat_xyzw: (N, 4) float64 unit quaternions x y z w, or None for position-only
            systems (UWB, BLE, 2D planners).
        name: what the user calls it ("ground truth", "RTAB-Map").
        source: where it came from (path, topic or tf chain selector).
        frame_id: the frame the poses are expressed in, if known.
        child_frame_id: the frame whose poses these are, if known.
        warnings: what the reader noticed (sorted stamps, dropped rows, axis conversion).
        cov6: (N, 6, 6) float64 covariance of each pose as the system reports it, or None.
            ROS order ``x y z rx ry rz``: metres² for the position block, rad² for the
            rotation block, the rotation about the fixed axes of ``frame_id`` (the
            convention of ``geometry_msgs/PoseWithCovariance``). Symmetric and finite;
            singular blocks are allowed (planar systems report zero z variance).
        notes: how the reader made it, for information (the tf chain it composed).
        indexed: the stamps are pose numbers, not times (a KITTI file without its times
            file: pose i is stamped i seconds), so durations, rates and clocks mean nothing.
    """

    stamps_ns: StampsNs
    positions_xyz: FloatArray
    quat_xyzw: FloatArray | None = None
    name: str = ""
    source: str = ""
    frame_id: str = ""
    child_frame_id: str = ""
    warnings: tuple[str, ...] = field(default=())
    cov6: FloatArray | None = None
    notes: tuple[str, ...] = field(default=())
    indexed: bool = False

    def __post_init__(self) -> None:
        """Copy the arrays, make them read-only and check shape, dtype and values."""
        stamps = np.array(self.stamps_ns, copy=True)
        if stamps.ndim != 1 or not np.issubdtype(stamps.dtype, np.integer):
            msg = (
                f"Trajectory {self.name!r}: stamps must be a 1-D integer array of nanoseconds, "
                f"got dtype {stamps.dtype} and shape {stamps.shape!r}."
            )
            raise TrajectoryError(msg)
        stamps = stamps.astype(np.int64, copy=False)
        n = stamps.shape[0]
        positions = np.array(self.positions_xyz, dtype=np.float64, copy=True)
        if positions.shape != (n, 3):
            msg = (
                f"Trajectory {self.name!r}: positions must have shape ({n}, 3), "
                f"got {positions.shape!r}."
            )
            raise TrajectoryError(msg)
        if not np.isfinite(positions).all():
            msg = f"Trajectory {self.name!r}: positions contain NaN or inf."
            raise TrajectoryError(msg)
        if n and float(np.abs(positions).max()) > MAX_COORDINATE_M:
            msg = (
                f"Trajectory {self.name!r}: a position is beyond ±{MAX_COORDINATE_M:g} m, "
                "which is no site's coordinate; check the units and the columns."
            )
            raise TrajectoryError(msg)
        if n > 1 and not (np.diff(stamps) > 0).all():
            msg = f"Trajectory {self.name!r}: stamps must be strictly increasing."
            raise TrajectoryError(msg)
        stamps.flags.writeable = False
        positions.flags.writeable = False
        object.__setattr__(self, "stamps_ns", stamps)
        object.__setattr__(self, "positions_xyz", positions)
        if self.quat_xyzw is not None:
            quat = np.array(self.quat_xyzw, dtype=np.float64, copy=True)
            if quat.shape != (n, 4):
                msg = (
                    f"Trajectory {self.name!r}: orientations must have shape ({n}, 4), "
                    f"got {quat.shape!r}."
                )
                raise TrajectoryError(msg)
            norms = row_norms(quat)
            # |norm - 1| <= 1e-6 everywhere: np.allclose(norms, 1.0, rtol=0, atol=1e-6), quicker
            if not np.isfinite(quat).all() or not (np.abs(norms - 1.0) <= 1e-6).all():
                msg = (
                    f"Trajectory {self.name!r}: orientations must be finite unit quaternions "
                    "(readers normalize them)."
                )
                raise TrajectoryError(msg)
            quat.flags.writeable = False
            object.__setattr__(self, "quat_xyzw", quat)
        if self.cov6 is not None:
            object.__setattr__(self, "cov6", self._checked_cov6(self.cov6, n))
        object.__setattr__(self, "warnings", tuple(self.warnings))
        # Names travel into terminals, reports, CSV cells, DXF text and file metadata: one
        # line, no control characters or bidirectional overrides.
        object.__setattr__(self, "name", display_text(self.name))

    def _checked_cov6(self, cov6: FloatArray, n: int) -> FloatArray:
        """Return a read-only float64 copy of ``cov6`` after checking shape and values."""
        cov = np.array(cov6, dtype=np.float64, copy=True)
        if cov.shape != (n, 6, 6):
            msg = (
                f"Trajectory {self.name!r}: pose covariances must have shape ({n}, 6, 6), "
                f"got {cov.shape!r}."
            )
            raise TrajectoryError(msg)
        if not np.isfinite(cov).all():
            msg = f"Trajectory {self.name!r}: pose covariances contain NaN or inf."
            raise TrajectoryError(msg)
        scale = max(float(np.abs(cov).max(initial=0.0)), 1.0)
        if not np.allclose(cov, cov.transpose(0, 2, 1), rtol=0.0, atol=1e-9 * scale):
            msg = (
                f"Trajectory {self.name!r}: pose covariances must be symmetric; check the "
                "order of the 36 values (row-major, x y z rx ry rz)."
            )
            raise TrajectoryError(msg)
        cov.flags.writeable = False
        return cov

    @property
    def has_covariance(self) -> bool:
        """Whether the trajectory carries per-pose covariances."""
        return self.cov6 is not None

    def __len__(self) -> int:
        """Return the number of poses."""
        return int(self.stamps_ns.shape[0])

    @property
    def has_orientation(self) -> bool:
        """Whether the trajectory carries orientations."""
        return self.quat_xyzw is not None

    @property
    def duration_s(self) -> float:
        """Time from the first to the last pose, in seconds."""
        if len(self) == 0:
            return 0.0
        return float(self.stamps_ns[-1] - self.stamps_ns[0]) / _NS_PER_S

    @property
    def length_m(self) -> float:
        """Path length: sum of the distances between consecutive positions, in metres."""
        return float(self.step_lengths_m().sum())

    @property
    def rate_hz(self) -> float:
        """Median pose rate in Hz (0 when it cannot be told)."""
        if len(self) < 2:
            return 0.0
        median_dt_ns = median(np.diff(self.stamps_ns))
        return _NS_PER_S / median_dt_ns if median_dt_ns > 0 else 0.0

    def step_lengths_m(self) -> FloatArray:
        """Return the (N - 1,) distances between consecutive positions, in metres."""
        out: FloatArray = row_norms(np.diff(self.positions_xyz, axis=0))
        return out

    def distances_m(self) -> FloatArray:
        """Return the (N,) distance travelled from the first pose, in metres."""
        out: FloatArray = np.concatenate(([0.0], np.cumsum(self.step_lengths_m())))
        return out

    def times_s(self) -> FloatArray:
        """Return the (N,) seconds since the first pose (float; for plots and outputs)."""
        if len(self) == 0:
            return np.zeros(0)
        out: FloatArray = (self.stamps_ns - self.stamps_ns[0]).astype(np.float64) / _NS_PER_S
        return out

    def gaps(self, max_gap_ns: int) -> list[tuple[int, int]]:
        """Return the ``(start_ns, end_ns)`` of every interval between poses longer than max gap.

        Args:
            max_gap_ns: longest interval that is not a gap, in nanoseconds.
        """
        if len(self) < 2:
            return []
        dt = np.diff(self.stamps_ns)
        idx = np.flatnonzero(dt > max_gap_ns)
        return [(int(self.stamps_ns[i]), int(self.stamps_ns[i + 1])) for i in idx]

    def tracking_losses(self, min_gap_ns: int) -> list[tuple[int, int]]:
        """Return the ``(start_ns, end_ns)`` of every tracking loss, judged by this rate.

        An interval is a loss when longer than ``min_gap_ns`` and than five median
        intervals (:func:`loceval.core.gaps.gap_threshold_ns`).

        Args:
            min_gap_ns: the floor, in nanoseconds (the evaluation's maximum gap).
        """
        return tracking_losses(self.stamps_ns, min_gap_ns=min_gap_ns)

    def select(self, index: IntArray | BoolArray) -> Trajectory:
        """Return the poses at ``index`` (an increasing integer index or a boolean mask)."""
        quat = None if self.quat_xyzw is None else self.quat_xyzw[index]
        cov = None if self.cov6 is None else self.cov6[index]
        return replace(
            self,
            stamps_ns=self.stamps_ns[index],
            positions_xyz=self.positions_xyz[index],
            quat_xyzw=quat,
            cov6=cov,
        )

    def shifted(self, offset_ns: int) -> Trajectory:
        """Return the trajectory with ``offset_ns`` added to every stamp."""
        return replace(self, stamps_ns=self.stamps_ns + np.int64(offset_ns))

    def transformed(self, transform: SimilarityTransform) -> Trajectory:
        """Return the trajectory mapped by ``transform`` (world frame change).

        Covariances follow the map: ``J Σ Jᵀ`` with ``J = diag(s R, R)`` (positions scale,
        rotation vectors about fixed axes only turn).
        """
        quat = None if self.quat_xyzw is None else transform.apply_orientations(self.quat_xyzw)
        cov = None
        if self.cov6 is not None:
            jac = np.zeros((6, 6))
            jac[:3, :3] = transform.scale * transform.rotation
            jac[3:, 3:] = transform.rotation
            cov = jac @ self.cov6 @ jac.T
        return replace(
            self,
            positions_xyz=transform.apply_positions(self.positions_xyz),
            quat_xyzw=quat,
            cov6=cov,
        )

    def with_body_offset(self, offset: SimilarityTransform) -> Trajectory:
        """Return the poses of a frame rigidly attached to the body: ``T_world_body · offset``.

        Used for the framework paper's device offset (rigid body origin -> camera centre).

        Raises:
            TrajectoryError: the trajectory has no orientations but the offset has a
                translation (the offset's direction would be unknown).
        """
        if self.quat_xyzw is None:
            if np.allclose(offset.translation, 0.0):
                return self
            msg = (
                f"Trajectory {self.name!r} has no orientations, so a device offset with a "
                "translation cannot be applied; record the rigid body's orientation or drop "
                "the offset."
            )
            raise TrajectoryError(msg)
        r_world_body = Rotation.from_quat(self.quat_xyzw)
        lever_m = r_world_body.apply(np.array(offset.translation))
        positions = self.positions_xyz + lever_m
        quat = (r_world_body * Rotation.from_matrix(offset.rotation)).as_quat()
        cov = None
        if self.cov6 is not None:
            # A rotation error δθ about fixed axes moves the offset point by δθ × lever:
            # δp' = δp - [lever]× δθ, and δθ' = δθ.
            jac = np.broadcast_to(np.eye(6), (len(self), 6, 6)).copy()
            jac[:, :3, 3:] = -skew(lever_m)
            cov = jac @ self.cov6 @ jac.transpose(0, 2, 1)
        return replace(self, positions_xyz=positions, quat_xyzw=quat, cov6=cov)

    @property
    def span_words(self) -> str:
        """The time it spans for a sentence (``"12.3 s"``), or that it has no times.

        A KITTI file without its times file is numbered, not stamped: ``"no timestamps
        (poses numbered)"``, never its pose count read as seconds (issue 44).
        """
        return NO_TIMES if self.indexed else format_duration(self.duration_s)

    @property
    def loss_words(self) -> str:
        """What a gap in this trajectory is: tracking loss, or a tf chain's link without data."""
        return "a link of its tf chain without data" if "@tf:" in self.source else "tracking loss"

    def with_warnings(self, *warnings: str) -> Trajectory:
        """Return the trajectory with ``warnings`` appended."""
        return replace(self, warnings=(*self.warnings, *warnings))

    def without_orientation(self) -> Trajectory:
        """Return the positions only (a covariance stays: its position block still holds)."""
        return replace(self, quat_xyzw=None)
