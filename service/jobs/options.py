"""From the front doors' typed options to the core's and the exporters' option objects.

Both front doors hold the options of :data:`loceval.options.OPTIONS` under the same keys:
the CLI in its parsed arguments (``args.max_dt_s``), the HTTP API in
:class:`service.schemas.evaluations.EvaluationOptions`; both are made from the table, and
:func:`option_values` reads either by key. :func:`config_from_options` builds the core's
:class:`~loceval.evaluation.EvaluationConfig` from the table (each of its fields that is an
option, by :func:`typed_value`) and :func:`export_from_options` the exporters' options, so a
value means the same thing, and fails with the same message, on both, and again when a
stored request is read for its job. A text option has one grammar (:func:`parse_text`): its
parser's (the form, the bounds), then the pattern the API's schema declares (plain decimals:
a pattern cannot bound ``1e3``); the CLI, the API and a stored request all take exactly
the texts the schema says. Nothing here supplies a default: the table does, and nothing
here restates the options: a new one is read by key where it is used.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping, Sequence
from dataclasses import fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from loceval.checkpoints.config import CheckpointConfig
from loceval.core.geometry import SimilarityTransform
from loceval.errors import InputError
from loceval.evaluation import EvaluationConfig, Tolerance, parse_offset
from loceval.options import AUTO, OPTIONS, OptionKind, check_option, option
from loceval.registration.alignment import AlignWindow

if TYPE_CHECKING:
    from exporters.options import ExportOptions
    from loceval.radio_evaluation import RangingConfig

__all__ = [
    "CONTROL_POINTS_NO_TOLERANCE",
    "OptionValues",
    "artifact_names",
    "check_device_choice",
    "check_pattern",
    "checkpoints_from_options",
    "config_from_options",
    "device_offset",
    "export_from_options",
    "fail_on_from_options",
    "is_auto",
    "offset_or_none",
    "option_values",
    "parse_text",
    "ranging_from_options",
    "typed_value",
]


CONTROL_POINTS_NO_TOLERANCE: Final = (
    "A tolerance verdict is judged along a trajectory, and the reference is a control-point "
    "survey: its points are scored by the Hilti tiers and the recall within each threshold, "
    "with no verdict to gate on; leave the tolerance (and the gate on it) out."
)
"""Why a control-point evaluation refuses a tolerance (a gate on it would pass unjudged)."""


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


def _site(text: str) -> object:
    from exporters.cad.site import parse_site  # noqa: PLC0415  (the exporters load on use)

    return parse_site(text)


def _crs(text: str) -> str:
    from exporters.options import ExportOptions  # noqa: PLC0415

    return str(ExportOptions(crs=text).crs)


def _tag_offset(text: str) -> object:
    from loceval.radio_evaluation import parse_tag_offset  # noqa: PLC0415  (the radio stack)

    return parse_tag_offset(text)


TEXT_PARSERS: Final[Mapping[str, Callable[[str], Any]]] = {
    "align_first": AlignWindow.parse,
    "offset": parse_offset,
    "tolerance": Tolerance.parse,
    "site": _site,
    "crs": _crs,
    "tag_offset_xyz": _tag_offset,
}
"""The parser of each text option that has a grammar (a pattern in the table)."""


def parse_text(key: str, text: str) -> Any:  # noqa: ANN401  (the option's own type)
    """Parse a text option by its one grammar, the same at every front door.

    Its parser runs first, so a text of the wrong form or out of bounds gets the parser's
    message (which says more); then the text must match the option's pattern, the grammar the
    API's schema declares: plain decimal numbers, no exponent (``1e-1@95`` is refused, and
    ``0.1@95`` taken, by the CLI, the API and a stored request alike).

    Raises:
        InputError: the text is not of the option's grammar; the error carries ``key``.
    """
    value = TEXT_PARSERS[key](text)
    check_pattern(key, text)
    return value


def typed_value(key: str, raw: Any) -> Any:  # noqa: ANN401  (the option's own type)
    """Return a front door's value of an option as the core takes it, by the option's kind.

    A choice becomes its enum member, a list of numbers a tuple, a text with a grammar its
    parsed value (:func:`parse_text`; None when not given, or empty where its grammar allows
    that); other kinds are taken as they are (bounds are checked where the value is used).

    Raises:
        InputError: the value cannot be used; the error carries ``key``.
    """
    spec = option(key)
    if spec.kind is OptionKind.CHOICE and spec.choices:
        return type(spec.choices[0])(raw)  # the choices' StrEnum (or str)
    if spec.kind is OptionKind.NUMBERS and raw is not None:
        return tuple(raw)
    if spec.kind is OptionKind.TEXT and key in TEXT_PARSERS:
        if raw is None or (not raw.strip() and not spec.pattern_problem(raw)):
            return None  # not given (an empty text where the grammar allows one)
        return parse_text(key, raw)
    return raw


_CONFIG_OPTIONS: Final = frozenset(s.key for s in OPTIONS if s.group == "evaluation")
"""The options of the core's evaluation (those of :class:`EvaluationConfig`'s fields are
taken from the table by name)."""


def ranging_from_options(options: object) -> RangingConfig:
    """Return the core's ranging options.

    Raises:
        InputError: a value cannot be used (the error carries the option's key).
    """
    from loceval.radio_evaluation import RangingConfig, parse_solvers  # noqa: PLC0415

    values = option_values(options)
    if str(values["dims"]) not in {"2", "3"}:
        msg = f"The number of dimensions must be 2 or 3, got {values['dims']!r}."
        raise InputError(msg, option="dims")
    return RangingConfig(
        solvers=parse_solvers(list(values["solve"])),
        dims=int(values["dims"]),
        epoch_s=values["epoch_s"],
        tag_height_m=values["tag_height_m"],
        tag_offset_xyz=typed_value("tag_offset_xyz", values["tag_offset_xyz"]),
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
    auto_drift = is_auto(values["clock_drift_ppm"])
    check_option("clutter_m", values["clutter_m"], unit="metres")  # the map's, checked as early
    fail_on_from_options(values)  # a gate that could never close fails before the evaluation
    checkpoints_from_options(values)  # control-point options fail as fast as the others
    # The options that are not one field each: auto values, the offset's two sources, a name.
    special: dict[str, Callable[[], Any]] = {
        "time_offset_s": lambda: 0.0 if auto_time else float(values["time_offset_s"]),
        "reference_offset": lambda: device_transform or typed_value("offset", values["offset"]),
        "worst_count": lambda: values["worst"],
        "auto_time_offset": lambda: auto_time,
        "clock_drift_ppm": lambda: 0.0 if auto_drift else float(values["clock_drift_ppm"]),
        "auto_clock_drift": lambda: auto_drift,
        "auto_device": lambda: is_auto(values["device"]),
        "reference_offset_source": lambda: "given" if device_transform is None else "urdf",
    }
    given: dict[str, Any] = {}
    for entry in fields(EvaluationConfig):  # in the fields' order: errors come as before
        if entry.name in special:
            given[entry.name] = special[entry.name]()
        elif entry.name in _CONFIG_OPTIONS:
            value = typed_value(entry.name, values[entry.name])
            if value is not None or entry.default is None:  # not given: the field's default
                given[entry.name] = value
    return EvaluationConfig(**given)


def fail_on_from_options(options: object) -> tuple[str, ...]:
    """Return the gate's conditions, checked against what the evaluation can judge.

    ``fail`` and ``undecided`` need a tolerance, ``worse`` a baseline
    (:func:`loceval.results.gate.check_fail_on`).

    Raises:
        InputError: an unknown condition, or one the evaluation cannot judge.
    """
    values = option_values(options)
    if not values.get("fail_on"):  # no gate: its module (the result reader) is not loaded
        return ()
    from loceval.results.gate import check_fail_on, parse_fail_on  # noqa: PLC0415  (numpy)

    fail_on = parse_fail_on(values.get("fail_on"))
    check_fail_on(
        fail_on,
        tolerance=bool(values.get("tolerance")),
        baseline=values.get("baseline") is not None,
    )
    return fail_on


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
        transform = parse_text("site", site)
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
        crs=typed_value("crs", values["crs"]),
        building_up=UpAxis(values["building_up"]),
        front_door=FrontDoor(front_door),
        fail_on=fail_on_from_options(values),
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
    """Parse an ``"x y z qx qy qz qw"`` offset (the core's parser); None when not given."""
    return parse_offset(offset) if offset else None


def check_pattern(key: str, value: str | None) -> None:
    """Check a text option against its pattern, the grammar the API's schema declares.

    :func:`parse_text` calls it after the option's parser, whose message says more about a
    text of the wrong form; what is left for the pattern is what the parser forgives
    (exponents, other digits and spaces), refused at every front door alike.

    Raises:
        InputError: the text does not match; the error carries ``key``.
    """
    problem = option(key).pattern_problem(value)
    if problem:
        raise InputError(problem, option=key)
