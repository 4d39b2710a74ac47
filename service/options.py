"""From the front doors' typed options to the core's and the exporters' option objects.

Both front doors hold the options of :data:`loceval.options.OPTIONS` under the same keys:
the CLI in its parsed arguments (``args.max_dt_s``), the HTTP API in
:class:`service.schemas.EvaluationOptions`. :func:`config_from_options` and
:func:`export_from_options` take either, so a value means the same thing, and fails with
the same message, on both. Nothing here supplies a default: the table does.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from loceval.calibration.offsets import DeviceSource
from loceval.checkpoints.config import CheckpointConfig
from loceval.core.geometry import SimilarityTransform
from loceval.errors import InputError
from loceval.evaluation import EvaluationConfig, Tolerance, parse_offset
from loceval.metrics.pose_errors import RPEUnit
from loceval.options import AUTO, check_option
from loceval.registration.alignment import AlignMethod, AlignWindow
from loceval.registration.association import AssociationMethod

if TYPE_CHECKING:
    from exporters.options import ExportOptions
    from loceval.radio_evaluation import RangingConfig

__all__ = [
    "EvaluationValues",
    "ExportValues",
    "RangingValues",
    "artifact_names",
    "checkpoints_from_options",
    "config_from_options",
    "device_offset",
    "export_from_options",
    "is_auto",
    "offset_or_none",
    "ranging_from_options",
]


class EvaluationValues(Protocol):
    """The evaluation options as a front door holds them (keys of ``OPTIONS``)."""

    @property
    def association(self) -> str:
        """The association method."""

    @property
    def max_dt_s(self) -> float:
        """Nearest matching's largest time difference, seconds."""

    @property
    def max_gap_s(self) -> float:
        """The longest reference gap bridged, seconds."""

    @property
    def time_offset_s(self) -> float | str:
        """Added to the estimate's stamps, seconds; ``auto``: estimated from the motion."""

    @property
    def device(self) -> object:
        """The device offset's source; ``auto``: estimated from the motion."""

    @property
    def align(self) -> str:
        """The alignment method."""

    @property
    def align_first(self) -> str | None:
        """The alignment window (``"100"`` poses or ``"5s"``)."""

    @property
    def calibrate_at_s(self) -> float | None:
        """Calibrate alignment: seconds after the first matched pose."""

    @property
    def rpe_delta(self) -> float:
        """The RPE delta."""

    @property
    def rpe_unit(self) -> str:
        """What the RPE delta counts."""

    @property
    def rpe_all_pairs(self) -> bool:
        """Every pose starts an RPE pair."""

    @property
    def thresholds_m(self) -> Sequence[float]:
        """Distances of the share-within figures, metres."""

    @property
    def tolerance(self) -> str | None:
        """The verdict's tolerance, ``METRES@PERCENT``."""

    @property
    def worst(self) -> int:
        """How many greatest errors to list."""

    @property
    def no_ci(self) -> bool:
        """Skip the confidence intervals and comparisons."""

    @property
    def reference_sigma_m(self) -> float | None:
        """The reference's per-axis standard deviation, metres."""

    @property
    def planar(self) -> bool:
        """Measure position errors in x-y only."""

    @property
    def visit_radius_m(self) -> float | None:
        """Control points: how near a stop must be to a point, metres."""

    @property
    def align_points(self) -> Sequence[str] | None:
        """Control points: the ids that fix the alignment."""

    @property
    def stop_speed_mps(self) -> float:
        """Control points: the speed below which the device stands still."""

    @property
    def stop_min_s(self) -> float:
        """Control points: how long the device must stand still, seconds."""


class ExportValues(Protocol):
    """The artifact options as a front door holds them (keys of ``OPTIONS``)."""

    @property
    def units(self) -> str:
        """CAD units."""

    @property
    def site(self) -> str | None:
        """The site transform, ``"tx ty tz yaw_deg"``."""

    @property
    def site_matrix(self) -> Path | Sequence[Sequence[float]] | None:
        """The site as a 4x4 matrix (the CLI: a file holding it)."""

    @property
    def simplify_m(self) -> float:
        """CAD polyline tolerance, metres."""

    @property
    def crs(self) -> str | None:
        """The projected coordinate reference system, ``"EPSG:25832"``."""

    @property
    def building_up(self) -> str:
        """The up axis of a building mesh file."""


class RangingValues(Protocol):
    """The ranging options as a front door holds them (group ``ranging`` of ``OPTIONS``)."""

    @property
    def solve(self) -> Sequence[str]:
        """The positioning algorithms."""

    @property
    def dims(self) -> str:
        """``"2"`` or ``"3"``."""

    @property
    def epoch_s(self) -> float:
        """The epoch length, seconds."""

    @property
    def tag_height_m(self) -> float | None:
        """The tag's height in 2D, metres."""

    @property
    def tag_offset_xyz(self) -> str | None:
        """The tag in the reference body frame, ``"x y z"``."""

    @property
    def outlier_threshold_m(self) -> float:
        """The outlier threshold, metres."""

    @property
    def distance_bin_m(self) -> float:
        """The error-versus-distance bin width, metres."""


def ranging_from_options(options: RangingValues) -> RangingConfig:
    """Return the core's ranging options.

    Raises:
        InputError: a value cannot be used (the error carries the option's key).
    """
    from loceval.radio_evaluation import RangingConfig, parse_solvers, parse_tag_offset  # noqa: PLC0415

    if str(options.dims) not in {"2", "3"}:
        msg = f"The number of dimensions must be 2 or 3, got {options.dims!r}."
        raise InputError(msg, option="dims")
    return RangingConfig(
        solvers=parse_solvers(list(options.solve)),
        dims=int(options.dims),
        epoch_s=options.epoch_s,
        tag_height_m=options.tag_height_m,
        tag_offset_xyz=parse_tag_offset(options.tag_offset_xyz),
        outlier_threshold_m=options.outlier_threshold_m,
        distance_bin_m=options.distance_bin_m,
    )


def config_from_options(
    options: EvaluationValues,
    *,
    reference_offset: SimilarityTransform | None = None,
    reference_offset_source: DeviceSource = "given",
) -> EvaluationConfig:
    """Return the core's options.

    Args:
        options: the front door's options.
        reference_offset: the device offset, already read (see :func:`device_offset`).
        reference_offset_source: ``urdf`` when it was read from a URDF or a bag.

    Raises:
        InputError: a value cannot be used (the error carries the option's key).
    """
    auto_time = is_auto(options.time_offset_s)
    checkpoints_from_options(options)  # control-point options fail as fast as the others
    return EvaluationConfig(
        association=AssociationMethod(options.association),
        max_dt_s=options.max_dt_s,
        max_gap_s=options.max_gap_s,
        time_offset_s=0.0 if auto_time else float(options.time_offset_s),
        align=AlignMethod(options.align),
        align_first=AlignWindow.parse(options.align_first),
        calibrate_at_s=options.calibrate_at_s,
        reference_offset=reference_offset,
        rpe_delta=options.rpe_delta,
        rpe_unit=RPEUnit(options.rpe_unit),
        rpe_all_pairs=options.rpe_all_pairs,
        thresholds_m=tuple(options.thresholds_m),
        tolerance=Tolerance.parse(options.tolerance) if options.tolerance else None,
        worst_count=options.worst,
        no_ci=options.no_ci,
        reference_sigma_m=options.reference_sigma_m,
        auto_time_offset=auto_time,
        auto_device=is_auto(options.device),
        reference_offset_source=reference_offset_source,
        planar=options.planar,
    )


def artifact_names(formats: Sequence[str] | None) -> list[str] | None:
    """Return the artifact file names that ``formats`` name (``dxf`` -> ``paths.dxf``).

    Raises:
        ExportOptionsError: a name that is neither an artifact nor a format alias.
    """
    if formats is None:
        return None
    from exporters import artifact_name  # noqa: PLC0415  (the exporters load on use)

    return list(dict.fromkeys(artifact_name(f) for f in formats))


def is_auto(value: object) -> bool:
    """Return whether an option's value is ``auto`` (estimated from the data)."""
    return isinstance(value, str) and value == AUTO


def checkpoints_from_options(options: EvaluationValues) -> CheckpointConfig:
    """Return the options of a control-point reference.

    Raises:
        InputError: a value cannot be used (the error carries the option's key).
    """
    return CheckpointConfig(
        visit_radius_m=options.visit_radius_m,
        align_points=tuple(options.align_points or ()),
        stop_speed_mps=options.stop_speed_mps,
        stop_min_s=options.stop_min_s,
    )


def export_from_options(
    options: ExportValues, *, evaluation_id: str = "", building: Path | None = None
) -> ExportOptions:
    """Return the artifact options, checked before the evaluation runs so bad ones fail fast.

    Args:
        options: the front door's options.
        evaluation_id: the id named in every file's metadata.
        building: a building mesh for the glTF scene (the CLI only).

    Raises:
        InputError: both a site and a site matrix, or an option's value cannot be used.
    """
    from exporters import ExportOptions  # noqa: PLC0415
    from exporters.cad.placement import (  # noqa: PLC0415
        check_options,
        parse_site,
        parse_units,
        read_site_matrix,
        site_from_values,
    )
    from exporters.options import UpAxis  # noqa: PLC0415

    matrix = options.site_matrix
    if options.site and matrix is not None:
        msg = "Give the site transform either as a site or as a site matrix, not both."
        raise InputError(msg, option="site_matrix")
    transform = SimilarityTransform.identity()
    if options.site:
        transform = parse_site(options.site)
    elif isinstance(matrix, Path):
        transform = read_site_matrix(matrix)
    elif matrix is not None:
        values = [float(v) for row in matrix for v in row]
        transform = site_from_values(values, where="the site matrix")
    check_option("simplify_m", options.simplify_m, unit="metres")
    export = ExportOptions(
        units=parse_units(options.units),
        site=transform,
        simplify_m=options.simplify_m,
        building=building,
        evaluation_id=evaluation_id,
        crs=options.crs,
        building_up=UpAxis(options.building_up),
    )
    check_options(export)
    return export


def device_offset(
    path: Path, *, from_link: str, to_link: str, offset: str | None = None
) -> SimilarityTransform:
    """Return the rigid body -> sensor offset from a URDF or from a bag's ``/tf_static``.

    Raises:
        InputError: an ``offset`` is given as well, or a link is not named.
        ReaderError: the file cannot be read or the links are not connected.
    """
    if offset:
        msg = "Give the device offset either as an offset or from a device file, not both."
        raise InputError(msg, option="device")
    if not (from_link and to_link):
        msg = (
            "A device file needs the rigid body's link and the sensor's link, e.g. "
            "from rigid_body to camera_link."
        )
        raise InputError(msg, option="device")
    if path.suffix.lower() in {".urdf", ".xml"}:
        from loceval.readers.urdf import read_urdf_offset  # noqa: PLC0415

        return read_urdf_offset(path, from_link=from_link, to_link=to_link)
    from loceval.readers.rosbag import read_bag_static_transform  # noqa: PLC0415

    return read_bag_static_transform(path, from_link, to_link)


def offset_or_none(offset: str | None) -> SimilarityTransform | None:
    """Parse an ``"x y z qx qy qz qw"`` offset; None when not given."""
    return parse_offset(offset) if offset else None
