"""From the front doors' typed options to the core's and the exporters' option objects.

Both front doors hold the options of :data:`loceval.options.OPTIONS` under the same keys:
the CLI in its parsed arguments (``args.max_dt_s``), the HTTP API in
:class:`service.schemas.evaluations.EvaluationOptions`; both are made from the table, and
:func:`option_values` reads either by key. :func:`config_from_options` and
:func:`export_from_options` parse each value once into its typed value (``Tolerance``,
``AlignWindow``, the enums, a transform), so a value means the same thing, and fails with
the same message, on both. Nothing here supplies a default: the table does, and nothing
here restates the options: a new one is read by key where it is used.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from loceval.checkpoints.config import CheckpointConfig
from loceval.core.geometry import SimilarityTransform
from loceval.errors import InputError
from loceval.evaluation import EvaluationConfig, Tolerance, parse_offset
from loceval.metrics.pose_errors import RPEUnit
from loceval.options import AUTO, check_option, option
from loceval.registration.alignment import AlignMethod, AlignWindow
from loceval.registration.association import AssociationMethod

if TYPE_CHECKING:
    from exporters.options import ExportOptions
    from loceval.radio_evaluation import RangingConfig

__all__ = [
    "OptionValues",
    "artifact_names",
    "check_device_choice",
    "check_pattern",
    "checkpoints_from_options",
    "config_from_options",
    "device_offset",
    "export_from_options",
    "is_auto",
    "offset_or_none",
    "option_values",
    "ranging_from_options",
]


OptionValues = Mapping[str, Any]
"""The options as a front door holds them, by the table's keys (values as it typed them)."""


def option_values(options: object) -> OptionValues:
    """Return a front door's options by key: the CLI's parsed arguments or the API's model.

    Raises:
        TypeError: neither (a bug).
    """
    if isinstance(options, Mapping):
        return options
    if isinstance(options, argparse.Namespace):
        return vars(options)
    fields = getattr(type(options), "model_fields", None)  # a pydantic model, not imported here
    if fields is not None:
        return {key: getattr(options, key) for key in fields}  # nested models kept
    msg = f"Options come as parsed arguments, a model or a mapping, not {type(options).__name__}."
    raise TypeError(msg)


def ranging_from_options(options: object) -> RangingConfig:
    """Return the core's ranging options.

    Raises:
        InputError: a value cannot be used (the error carries the option's key).
    """
    from loceval.radio_evaluation import RangingConfig, parse_solvers, parse_tag_offset  # noqa: PLC0415

    values = option_values(options)
    if str(values["dims"]) not in {"2", "3"}:
        msg = f"The number of dimensions must be 2 or 3, got {values['dims']!r}."
        raise InputError(msg, option="dims")
    return RangingConfig(
        solvers=parse_solvers(list(values["solve"])),
        dims=int(values["dims"]),
        epoch_s=values["epoch_s"],
        tag_height_m=values["tag_height_m"],
        tag_offset_xyz=parse_tag_offset(values["tag_offset_xyz"]),
        outlier_threshold_m=values["outlier_threshold_m"],
        distance_bin_m=values["distance_bin_m"],
    )


def config_from_options(
    options: object,
    *,
    front_door: str = "service",
    device_transform: SimilarityTransform | None = None,
) -> EvaluationConfig:
    """Return the core's options: each value parsed once, here, into its typed value.

    Args:
        options: the front door's options (see :func:`option_values`).
        front_door: ``cli`` or ``service``: how a message names an option.
        device_transform: the device offset read from a device file (see
            :func:`device_offset`); without it the ``offset`` option's, if given.

    Raises:
        InputError: a value cannot be used (the error carries the option's key).
    """
    values = option_values(options)
    check_device_choice(values, front_door=front_door)
    auto_time = is_auto(values["time_offset_s"])
    check_option("clutter_m", values["clutter_m"], unit="metres")  # the map's, checked as early
    checkpoints_from_options(values)  # control-point options fail as fast as the others
    tolerance = values["tolerance"]
    return EvaluationConfig(
        association=AssociationMethod(values["association"]),
        max_dt_s=values["max_dt_s"],
        max_gap_s=values["max_gap_s"],
        time_offset_s=0.0 if auto_time else float(values["time_offset_s"]),
        align=AlignMethod(values["align"]),
        align_first=AlignWindow.parse(values["align_first"]),
        calibrate_at_s=values["calibrate_at_s"],
        reference_offset=device_transform or offset_or_none(values["offset"]),
        rpe_delta=values["rpe_delta"],
        rpe_unit=RPEUnit(values["rpe_unit"]),
        rpe_all_pairs=values["rpe_all_pairs"],
        thresholds_m=tuple(values["thresholds_m"]),
        tolerance=Tolerance.parse(tolerance) if tolerance else None,
        worst_count=values["worst"],
        no_ci=values["no_ci"],
        reference_sigma_m=values["reference_sigma_m"],
        auto_time_offset=auto_time,
        auto_device=is_auto(values["device"]),
        reference_offset_source="given" if device_transform is None else "urdf",
        planar=values["planar"],
        min_excursion_s=values["min_excursion_s"],
    )


def check_device_choice(values: OptionValues, *, front_door: str) -> None:
    """Refuse a device offset given twice: as ``offset`` and as ``device`` (a file or auto).

    The one check of this rule; its words name the options the way ``front_door`` does.

    Raises:
        InputError: both are given.
    """
    device = values["device"]
    if not values["offset"] or device is None:
        return
    if front_door != "cli":
        msg = "Give the device offset either as offset or as device, not both."
    elif is_auto(device):
        msg = "Give the device offset either with --offset or as --device auto, not both."
    else:
        msg = "Give the device offset either with --offset or with --device, not both."
    raise InputError(msg, option="device")


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


def checkpoints_from_options(options: object) -> CheckpointConfig:
    """Return the options of a control-point reference.

    Raises:
        InputError: a value cannot be used (the error carries the option's key).
    """
    values = option_values(options)
    return CheckpointConfig(
        visit_radius_m=values["visit_radius_m"],
        align_points=tuple(values["align_points"] or ()),
        stop_speed_mps=values["stop_speed_mps"],
        stop_min_s=values["stop_min_s"],
    )


def export_from_options(
    options: object,
    *,
    front_door: str,
    evaluation_id: str = "",
    building: Path | None = None,
) -> ExportOptions:
    """Return the artifact options, checked before the evaluation runs so bad ones fail fast.

    Args:
        options: the front door's options.
        front_door: ``cli`` or ``service`` (the page and the API): how the report names
            an option (:class:`~exporters.options.FrontDoor`).
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
    from exporters.options import FrontDoor, UpAxis  # noqa: PLC0415

    values = option_values(options)
    matrix = values["site_matrix"]
    site = values["site"]
    if site and matrix is not None:
        msg = "Give the site transform either as a site or as a site matrix, not both."
        raise InputError(msg, option="site_matrix")
    transform = SimilarityTransform.identity()
    if site:
        transform = parse_site(site)
    elif isinstance(matrix, Path):
        transform = read_site_matrix(matrix)
    elif matrix is not None:
        numbers = [float(v) for row in matrix for v in row]
        transform = site_from_values(numbers, where="the site matrix")
    check_option("simplify_m", values["simplify_m"], unit="metres")
    export = ExportOptions(
        units=parse_units(values["units"]),
        site=transform,
        simplify_m=values["simplify_m"],
        building=building,
        evaluation_id=evaluation_id,
        crs=values["crs"],
        building_up=UpAxis(values["building_up"]),
        front_door=FrontDoor(front_door),
    )
    check_options(export)
    return export


def device_offset(path: Path, *, from_link: str, to_link: str) -> SimilarityTransform:
    """Return the rigid body -> sensor offset from a URDF or from a bag's ``/tf_static``.

    Raises:
        InputError: a link is not named.
        ReaderError: the file cannot be read or the links are not connected.
    """
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


def check_pattern(key: str, value: str | None) -> None:
    """Check a text option against its pattern: the HTTP API's grammar of the option.

    The API's schema declares the pattern and the service holds requests to it, so that
    schema and server take the same texts. Call this after the option's parser, whose
    message says more about a text of the wrong form; what is left for the pattern is what
    the parser forgives (exponents, other digits and spaces). The CLI keeps the parsers'.

    Raises:
        InputError: the text does not match; the error carries ``key``.
    """
    problem = option(key).pattern_problem(value)
    if problem:
        raise InputError(problem, option=key)
