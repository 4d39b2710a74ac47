"""The one table of evaluation options: key, kind, default, bounds, choices and help of each.

Every front door is built from :data:`OPTIONS`: the CLI's ``loceval evaluate`` flags, the HTTP
API's ``EvaluationOptions`` schema, the defaults and checks of ``EvaluationConfig``. A key
(``max_dt_s``) is what the API and the options document call the option; ``flag`` (``--max-dt``,
from ``cli_name``) is the CLI's name for it and ``words`` ("the maximum time difference") is how
messages name it without naming a front door. Errors about an option carry its key
(``InputError(msg, option="max_dt_s")``). Pure Python: the CLI's parser needs no numpy.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Final

from loceval import optionspec as grammar
from loceval.errors import InputError
from loceval.optionspec import (
    AlignMethod,
    AssociationMethod,
    OptionKind,
    OptionSpec,
    OptionValue,
    RPEUnit,
    StampSource,
    Units,
    UpAxis,
)

__all__ = [
    "AUTO",
    "DEFAULT_THRESHOLDS_M",
    "OPTIONS",
    "AlignMethod",
    "AssociationMethod",
    "OptionKind",
    "OptionSpec",
    "OptionValue",
    "RPEUnit",
    "StampSource",
    "Units",
    "UpAxis",
    "check_option",
    "choice_default",
    "number_default",
    "option",
]

DEFAULT_THRESHOLDS_M: Final[tuple[float, ...]] = (0.05, 0.10, 0.15)
"""The reference-system paper's Fig. 7 thresholds, metres."""

AUTO: Final = "auto"
"""The value of an ``auto`` option that has the data decide."""

_MAX_S: Final = 1e9  # the largest span of seconds an option takes (31 years; more is a mistake)

OPTIONS: Final[tuple[OptionSpec, ...]] = (
    OptionSpec(
        "association",
        OptionKind.CHOICE,
        AssociationMethod.INTERPOLATE.value,
        "how estimate poses are matched to reference poses in time",
        "the association method",
        "associate",
        choices=tuple(AssociationMethod),
        label="Association",
    ),
    OptionSpec(
        "max_dt_s",
        OptionKind.NUMBER,
        0.01,
        "nearest association: the largest time difference of a match, seconds",
        "the maximum time difference",
        "max-dt",
        "S",
        minimum=0.0,
        maximum=3600.0,
        exclusive_minimum=True,
        label="Max time difference (s)",
    ),
    OptionSpec(
        "max_gap_s",
        OptionKind.NUMBER,
        0.1,
        "the longest reference gap bridged by interpolation, seconds",
        "the maximum gap",
        "max-gap",
        "S",
        minimum=1e-9,  # 1 ns, the resolution of stamps
        maximum=1e6,
        label="Max gap (s)",
    ),
    OptionSpec(
        "time_offset_s",
        OptionKind.NUMBER,
        0.0,
        "added to every estimate stamp, seconds; auto: estimated from the motion",
        "the time offset",
        "time-offset",
        "S|auto",
        minimum=-_MAX_S,
        maximum=_MAX_S,
        auto=True,
        label="Time offset (s)",
    ),
    OptionSpec(
        "clock_drift_ppm",
        OptionKind.NUMBER,
        0.0,
        "how fast the estimate's clock runs against the reference's, ppm (negative: slow), "
        "applied with the time offset at its first pose; auto: estimated from the motion, "
        "with any clock step",
        "the clock drift",
        "clock-drift",
        "PPM|auto",
        minimum=-1000.0,  # loceval.calibration.drift.MAX_RATE_PPM
        maximum=1000.0,
        auto=True,
        label="Clock drift (ppm)",
    ),
    OptionSpec(
        "stamp",
        OptionKind.CHOICE,
        StampSource.HEADER.value,
        "bags: stamps from the message header or the bag's receive time",
        "the stamp source",
        "stamp",
        choices=tuple(StampSource),
        group="reading",
        label="Stamps",
    ),
    OptionSpec(
        "align",
        OptionKind.CHOICE,
        AlignMethod.SE3.value,
        "how the estimate is brought into the reference's frame",
        "the alignment method",
        "align",
        choices=tuple(AlignMethod),
        label="Alignment",
    ),
    OptionSpec(
        "align_first",
        OptionKind.TEXT,
        None,
        "align on the first N poses or N seconds (10s)",
        "the alignment window",
        "align-first",
        "N|Ns",
        max_length=32,
        pattern=grammar.ALIGN_FIRST_PATTERN,
        label="Align on the first",
    ),
    OptionSpec(
        "calibrate_at_s",
        OptionKind.NUMBER,
        None,
        "calibrate alignment: seconds after the first matched pose",
        "the calibration time",
        "calibrate-at",
        "S",
        minimum=0.0,
        maximum=_MAX_S,
        label="Calibration time (s)",
    ),
    OptionSpec(
        "offset",
        OptionKind.TEXT,
        None,
        'rigid body -> sensor "x y z qx qy qz qw", applied to the reference',
        "the device offset",
        "offset",
        '"x y z qx qy qz qw"',
        max_length=300,
        pattern=grammar.OFFSET_PATTERN,
        label="Device offset",
    ),
    OptionSpec(
        "device",
        OptionKind.DEVICE,
        None,
        "URDF (or a bag with /tf_static) giving the device offset between two links; "
        "auto: estimated from the motion",
        "the device file",
        "device",
        "FILE|auto",
        auto=True,
        label="Device file",
    ),
    OptionSpec(
        "rpe_delta",
        OptionKind.NUMBER,
        1.0,
        "the RPE delta (step), in the RPE unit",
        "the RPE delta",
        "rpe-delta",
        "D",
        minimum=0.0,
        maximum=_MAX_S,
        exclusive_minimum=True,
        label="RPE delta",
    ),
    OptionSpec(
        "rpe_unit",
        OptionKind.CHOICE,
        RPEUnit.FRAMES.value,
        "what the RPE step counts: frames, metres or seconds",
        "the RPE unit",
        "rpe-unit",
        choices=tuple(RPEUnit),
        label="RPE unit",
    ),
    OptionSpec(
        "rpe_all_pairs",
        OptionKind.SWITCH,
        False,  # noqa: FBT003  (a default, not a flag argument)
        "every pose starts an RPE pair (default: consecutive segments)",
        "all RPE pairs",
        "rpe-all-pairs",
        label="All RPE pairs",
    ),
    OptionSpec(
        "thresholds_m",
        OptionKind.NUMBERS,
        DEFAULT_THRESHOLDS_M,
        "distances for the share-within figures, metres",
        "the thresholds",
        "thresholds",
        "M,M,...",
        minimum=0.0,
        maximum=1e6,
        exclusive_minimum=True,
        max_length=20,
        label="Thresholds (m)",
    ),
    OptionSpec(
        "tolerance",
        OptionKind.TEXT,
        None,
        "pass/fail verdict: METRES@PERCENT of poses within, e.g. 0.10@95",
        "the tolerance",
        "tolerance",
        "M@PCT",
        max_length=40,
        pattern=grammar.TOLERANCE_PATTERN,
        example="0.10@95",
        label="Tolerance",
    ),
    *grammar.GATE_OPTIONS,
    OptionSpec(
        "worst",
        OptionKind.INTEGER,
        10,
        "how many of the greatest errors are listed",
        "the number of worst poses",
        "worst",
        "N",
        minimum=0,
        maximum=1000,
        label="Worst poses listed",
    ),
    OptionSpec(
        "units",
        OptionKind.CHOICE,
        Units.MM.value,
        "length units of the CAD files",
        "the CAD units",
        "units",
        choices=tuple(Units),
        group="export",
        label="CAD units",
    ),
    OptionSpec(
        "site",
        OptionKind.TEXT,
        None,
        'evaluation frame -> model frame "tx ty tz yaw_deg": metres whatever the units, '
        "yaw in degrees counter-clockwise about Z from the model's (map's) x axis",
        "the site transform",
        "site",
        '"tx ty tz yaw_deg"',
        max_length=200,
        pattern=grammar.SITE_PATTERN,
        example="12.5 3.2 0 90",
        group="export",
        label="Site transform",
    ),
    OptionSpec(
        "site_matrix",
        OptionKind.MATRIX,
        None,
        "evaluation frame -> model frame as a 4x4 matrix (the CLI: a file holding it)",
        "the site matrix",
        "site-matrix",
        "FILE",
        group="export",
        label="Site matrix",
    ),
    OptionSpec(
        "simplify_m",
        OptionKind.NUMBER,
        0.001,
        "largest deviation the CAD polyline simplification may introduce, metres",
        "the simplification tolerance",
        "simplify",
        "M",
        minimum=0.0,
        maximum=1000.0,
        group="export",
        label="Path simplification (m)",
    ),
    OptionSpec(
        "crs",
        OptionKind.TEXT,
        None,
        "the projected coordinate reference system the site places the paths in, e.g. "
        "EPSG:25832 (the IFC then carries the site as its map conversion)",
        "the coordinate reference system",
        "crs",
        "AUTHORITY:CODE",
        max_length=64,
        pattern=grammar.CRS_PATTERN,
        example="EPSG:25832",
        group="export",
        label="Coordinate system",
    ),
    OptionSpec(
        "building_up",
        OptionKind.CHOICE,
        UpAxis.FORMAT.value,
        "a mesh building's up axis: format = y for GLB (glTF spec), z for OBJ/PLY/STL; or z, y",
        "the building model's up axis",
        "building-up",
        choices=tuple(UpAxis),
        group="export",
        label="Building model's up axis",
    ),
    OptionSpec(
        "formats",
        OptionKind.NAMES,
        None,
        "artifacts to write (default: all)",
        "the artifact names",
        "formats",
        "NAME,...",
        min_length=1,
        max_length=20,
        group="export",
        label="Files",
    ),
    OptionSpec(
        "building",
        OptionKind.FILE,
        None,
        "a building model (OBJ, PLY, STL, GLB or IFC) to put in the glTF scene and under "
        "the report's plan views, or a DXF floor plan (plan views only); an IFC's map "
        "conversion places the paths when no site is given (the API: the model's dataset id)",
        "the building model",
        "building",
        "FILE",
        max_length=64,
        group="export",
        label="Building model",
    ),
    OptionSpec(
        "no_ci",
        OptionKind.SWITCH,
        False,  # noqa: FBT003  (a default, not a flag argument)
        "skip the confidence intervals and the comparisons of estimates (ci95 null)",
        "the switch that turns confidence intervals off",
        "no-ci",
        label="No confidence intervals",
    ),
    OptionSpec(
        "reference_sigma_m",
        OptionKind.NUMBER,
        None,
        "the ground truth's own error, per-axis standard deviation in metres (0.0002)",
        "the reference's standard deviation",
        "reference-sigma",
        "M",
        minimum=0.0,
        maximum=10.0,
        example="0.0002",
        label="Reference std. dev. (m)",
    ),
    OptionSpec(
        "planar",
        OptionKind.SWITCH,
        False,  # noqa: FBT003  (a default, not a flag argument)
        "measure position errors in x-y only (height differences count as zero)",
        "the x-y only measurement",
        "planar",
        label="Planar (x-y only)",
    ),
    OptionSpec(
        "visits",
        OptionKind.TEXT,
        "auto",
        "control points: when the device stood on which point; auto finds the stops, or a "
        "visits table id,t_start,t_end, or a bag topic of arrivals BAG@TOPIC (the API: a "
        "visits table's dataset id)",
        "the visits",
        "visits",
        "auto|FILE|BAG@TOPIC",
        max_length=500,
        example="auto",
        label="Visits",
    ),
    OptionSpec(
        "visit_radius_m",
        OptionKind.NUMBER,
        None,
        "control points: how near a stop must be to a point to visit it, metres "
        "(default: half the smallest distance between two points)",
        "the visit radius",
        "visit-radius",
        "M",
        minimum=0.0,
        maximum=1e6,
        exclusive_minimum=True,
        label="Visit radius (m)",
    ),
    OptionSpec(
        "align_points",
        OptionKind.NAMES,
        None,
        "control points: ids of the points that fix the alignment; the rest are scored",
        "the alignment points",
        "align-points",
        "ID,...",
        min_length=1,
        max_length=1000,
        label="Alignment points",
    ),
    OptionSpec(
        "stop_speed_mps",
        OptionKind.NUMBER,
        0.05,
        "control points, visits auto: the speed below which the device stands still, m/s",
        "the stop speed",
        "stop-speed",
        "M/S",
        minimum=0.0,
        maximum=100.0,
        exclusive_minimum=True,
        label="Stop speed (m/s)",
    ),
    OptionSpec(
        "stop_min_s",
        OptionKind.NUMBER,
        1.0,
        "control points, visits auto: how long the device must stand still, seconds",
        "the minimum stop duration",
        "stop-min",
        "S",
        minimum=0.0,
        maximum=3600.0,
        exclusive_minimum=True,
        label="Shortest stop (s)",
    ),
    OptionSpec(
        "map",
        OptionKind.FILE,
        None,
        "the robot's occupancy grid map to measure against the building model's plan: "
        "map_server's map.yaml beside its image, a zip of both, or BAG@TOPIC of "
        "nav_msgs/msg/OccupancyGrid (the API: the dataset id, with a selector for a bag)",
        "the map",
        "map",
        "SOURCE",
        max_length=500,
        group="map",
        label="Map",
    ),
    OptionSpec(
        "map_estimate",
        OptionKind.TEXT,
        None,
        "the estimate whose alignment places the map on the plan (default: the first)",
        "the estimate placing the map",
        "map-estimate",
        "NAME",
        max_length=120,
        group="map",
        label="Estimate placing the map",
    ),
    OptionSpec(
        "clutter_m",
        OptionKind.NUMBER,
        0.5,
        "map: occupied cells farther than this from every plan wall after the best fit are "
        "clutter (furniture), metres",
        "the clutter distance",
        "clutter-distance",
        "M",
        minimum=0.0,
        maximum=100.0,
        exclusive_minimum=True,
        group="map",
        label="Clutter distance (m)",
    ),
    *grammar.TRIAL_OPTIONS,
    OptionSpec(
        "min_excursion_s",
        OptionKind.NUMBER,
        5.0,
        "a reference loss longer than this while the estimate goes on is an excursion, seconds",
        "the shortest excursion",
        "min-excursion",
        "S",
        minimum=0.0,
        maximum=_MAX_S,
        exclusive_minimum=True,
        label="Shortest excursion (s)",
    ),
    *grammar.RANGING_OPTIONS,
)
"""Every option, in the order ``--help`` and the API schema list them."""

_BY_KEY: Final[Mapping[str, OptionSpec]] = {spec.key: spec for spec in OPTIONS}


def option(key: str) -> OptionSpec:
    """Return the option named ``key``.

    Raises:
        KeyError: no such option (a bug: keys are fixed in :data:`OPTIONS`).
    """
    return _BY_KEY[key]


def number_default(key: str) -> float:
    """Return the default of a number option (:meth:`OptionSpec.number_default`)."""
    return option(key).number_default()


def choice_default(key: str) -> str:
    """Return the default of a choice or text option (:meth:`OptionSpec.text_default`)."""
    return option(key).text_default()


def check_option(key: str, value: float, *, unit: str = "") -> None:
    """Check a number (or one item of a list) against the option's bounds.

    Raises:
        InputError: the value is not finite or out of bounds; the error carries ``key``.
    """
    problem = option(key).bounds_problem(value, unit=unit)
    if problem:
        raise InputError(problem, option=key)
