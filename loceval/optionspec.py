"""The shapes of the options table: the choices (StrEnums) and one option's specification.

:mod:`loceval.options` holds the table itself (:data:`~loceval.options.OPTIONS`) and
re-exports these names. Pure Python, like the table, so the CLI builds its parser without
the numeric stack.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from enum import StrEnum
from typing import Final

__all__ = [
    "ALIGN_FIRST_PATTERN",
    "CRS_PATTERN",
    "GATE_OPTIONS",
    "OFFSET_PATTERN",
    "RANGING_OPTIONS",
    "SITE_PATTERN",
    "TAG_OFFSET_PATTERN",
    "TOLERANCE_PATTERN",
    "TRIAL_OPTIONS",
    "AlignMethod",
    "AssociationMethod",
    "OptionKind",
    "OptionSpec",
    "OptionValue",
    "RPEUnit",
    "StampSource",
    "Units",
    "UpAxis",
]


class AssociationMethod(StrEnum):
    """How estimate poses are matched to reference poses in time."""

    INTERPOLATE = "interpolate"
    NEAREST = "nearest"


class AlignMethod(StrEnum):
    """How the estimate is brought into the reference's frame."""

    SE3 = "se3"
    SIM3 = "sim3"
    ORIGIN = "origin"
    YAW = "yaw"
    CALIBRATE = "calibrate"
    NONE = "none"


class RPEUnit(StrEnum):
    """What the RPE delta counts."""

    FRAMES = "frames"
    METRES = "m"
    SECONDS = "s"


class StampSource(StrEnum):
    """Which stamps a bag's poses take: the message header's or the bag's receive time."""

    HEADER = "header"
    """``header.stamp`` of the message (of the transform, for tf): when it was measured."""
    RECEIVE = "receive"
    """The bag's receive (log) time: when the recorder got it."""


class UpAxis(StrEnum):
    """The up axis of a building mesh file (OBJ, PLY, STL, GLB).

    ``format``: the file format's own convention: Y for glTF/GLB (its specification says
    Y up), Z for OBJ, PLY and STL (as CAD programs export them). ``z`` and ``y`` override
    it, for a GLB written from Z-up data or an OBJ from a Y-up exporter.
    """

    FORMAT = "format"
    Z = "z"
    Y = "y"


class Units(StrEnum):
    """Length units of CAD output."""

    MM = "mm"
    CM = "cm"
    M = "m"

    @property
    def per_metre(self) -> float:
        """How many of these units make a metre."""
        return {"mm": 1000.0, "cm": 100.0, "m": 1.0}[self.value]


class OptionKind(StrEnum):
    """The type of an option's value (each front door spells it its own way)."""

    NUMBER = "number"
    """A finite float."""
    INTEGER = "integer"
    """An int."""
    SWITCH = "switch"
    """A bool, false by default (a CLI flag without a value)."""
    CHOICE = "choice"
    """One of ``choices``."""
    TEXT = "text"
    """A string in the option's own syntax, parsed by the core (``"0.10@95"``)."""
    NUMBERS = "numbers"
    """A list of finite floats (the CLI: separated by commas)."""
    NAMES = "names"
    """A list of names (the CLI: separated by commas)."""
    MATRIX = "matrix"
    """A 4x4 matrix (the CLI: a file holding it)."""
    DEVICE = "device"
    """A device file and two links (the API: an uploaded dataset's id and the links)."""
    FILE = "file"
    """A local file (CLI only)."""


_TYPED_BOUND: Final = 1e6
"""Bounds of this magnitude or more (or positive ones below its inverse) are not shown on a
form: no person types them; they only stop a mistake (:attr:`OptionSpec.bounds_hint`)."""

OptionValue = float | int | bool | str | tuple[float, ...] | tuple[str, ...] | None
"""The type of a default."""


@dataclass(frozen=True, slots=True)
class OptionSpec:
    """One option, as every front door shows it.

    Attributes:
        key: the option's key (the API's field, the options document's key, ``option=``
            of errors).
        kind: the type of its value.
        default: the value when not given (None: not set).
        help: one line for ``--help`` and the API schema's description.
        words: how messages name it, front-door neutral ("the maximum time difference").
        cli_name: the CLI's name of the flag, without its dashes (``max-dt``).
        metavar: the CLI's placeholder of the value.
        minimum: the least value (of each item, for lists), if bounded below.
        maximum: the greatest value (of each item, for lists), if bounded above.
        exclusive_minimum: ``minimum`` itself is not allowed.
        choices: the allowed values of a ``CHOICE``.
        max_length: the longest text, or the most items of a list.
        min_length: the fewest items of a list.
        pattern: a regular expression the text must match (the API declares it in its
            schema and checks it after the option's parser; see :meth:`pattern_problem`).
        example: an example value for the API's documentation.
        group: ``evaluation`` (the core's), ``reading``, ``export`` or ``ranging`` (only
            ``loceval ranging`` and the ranging request take these).
        api: the HTTP API takes it.
        cli: the CLI takes it.
        auto: the value may also be ``auto`` (estimated from the data; :data:`AUTO`).
        label: its short name on a form ("Max gap (s)"); ``help`` says what it does.
    """

    key: str
    kind: OptionKind
    default: OptionValue
    help: str
    words: str
    cli_name: str
    metavar: str | None = None
    minimum: float | None = None
    maximum: float | None = None
    exclusive_minimum: bool = False
    choices: tuple[str, ...] = ()
    max_length: int | None = None
    min_length: int | None = None
    pattern: str | None = None
    example: str | None = None
    group: str = "evaluation"
    api: bool = True
    cli: bool = True
    auto: bool = False
    label: str = ""

    def document(self) -> dict[str, object]:
        """Return the option as JSON: what a front door needs to offer and check it.

        The API's ``GET /options`` and the browser page's form are made from these.
        """
        default = list(self.default) if isinstance(self.default, tuple) else self.default
        return {
            "key": self.key,
            "kind": self.kind.value,
            "default": default,
            "help": self.help,
            "words": self.words,
            "flag": self.flag if self.cli else None,
            "metavar": self.metavar,
            "minimum": self.minimum,
            "maximum": self.maximum,
            "exclusive_minimum": self.exclusive_minimum,
            "choices": [str(c) for c in self.choices],
            "max_length": self.max_length,
            "min_length": self.min_length,
            "pattern": self.pattern,
            "example": self.example,
            "group": self.group,
            "auto": self.auto,
            "bounds": self.bounds_text,
            "bounds_hint": self.bounds_hint,
            "label": self.label,
        }

    @property
    def flag(self) -> str:
        """Return the CLI's flag (``--max-dt``)."""
        return f"--{self.cli_name}"

    @property
    def bounds_text(self) -> str:
        """Return the allowed range in words: ``"more than 0 and at most 3600"``."""
        parts = []
        if self.minimum is not None:
            below = "more than" if self.exclusive_minimum else "at least"
            parts.append(f"{below} {self.minimum:g}")
        if self.maximum is not None:
            parts.append(f"at most {self.maximum:g}")
        return " and ".join(parts)

    @property
    def bounds_hint(self) -> str:
        """Return the bounds a person would type, in words, for a form's hint.

        A bound that only stops nonsense (``1e+09`` seconds, ``1e-09`` as the least gap) is
        left out: a tiny positive minimum reads "more than 0", and a bound of a million or
        more is not shown. :attr:`bounds_text` keeps every bound for messages.
        """
        parts = []
        low = self.minimum
        if low is not None and abs(low) < _TYPED_BOUND:
            if 0 < low < 1 / _TYPED_BOUND:
                parts.append("more than 0")
            else:
                below = "more than" if self.exclusive_minimum else "at least"
                parts.append(f"{below} {low:g}")
        if self.maximum is not None and abs(self.maximum) < _TYPED_BOUND:
            parts.append(f"at most {self.maximum:g}")
        return " and ".join(parts)

    def number_default(self) -> float:
        """Return the default of a number option.

        Raises:
            TypeError: the option has no number default (a bug).
        """
        default = self.default
        if isinstance(default, bool) or not isinstance(default, int | float):
            msg = f"Option {self.key!r} has no number default."
            raise TypeError(msg)
        return float(default)

    def text_default(self) -> str:
        """Return the default of a choice or text option.

        Raises:
            TypeError: the option has no text default (a bug).
        """
        if not isinstance(self.default, str):
            msg = f"Option {self.key!r} has no text default."
            raise TypeError(msg)
        return self.default

    def bounds_problem(self, value: float, *, unit: str = "") -> str:
        """Return what is wrong with a number for this option ("" when it is fine)."""
        if self.within_bounds(value):
            return ""
        what = f"a finite number of {unit}" if unit else "a finite number"
        bounds = f" {self.bounds_text}" if self.bounds_text else ""
        words = self.words[0].upper() + self.words[1:]
        return f"{words} must be {what}{bounds}, got {value!r}."

    def within_bounds(self, value: float) -> bool:
        """Return whether ``value`` is finite and within the bounds."""
        if not math.isfinite(value):
            return False
        if self.minimum is not None and (
            value < self.minimum or (self.exclusive_minimum and value == self.minimum)
        ):
            return False
        return self.maximum is None or value <= self.maximum

    def pattern_problem(self, value: str | None) -> str:
        """Return what is wrong with a text for this option's pattern ("" when it matches)."""
        if value is None or self.pattern is None or re.fullmatch(self.pattern, value):
            return ""
        words = self.words[0].upper() + self.words[1:]
        like = f" like {self.example!r}" if self.example else ""
        numbers = (
            ", in plain decimal numbers (no exponent) within the bounds, separated by spaces"
            if "[0-9]" in self.pattern
            else ""
        )
        return f"{words} must read {self.metavar}{like}{numbers}, got {value!r}."


# The grammars of the text options: regular expressions the HTTP API declares and checks.
# Each takes a subset of what the option's parser takes (plain decimals, no exponent, the
# option's bounds spelled out in digits), so that the API's schema says exactly which texts
# the server takes: a pattern cannot bound "1e3" but can bound "1000". Every front door holds
# a text to its pattern after its parser (service.jobs.options.parse_text), so the CLI takes
# what the API takes. Only ASCII classes, groups and counts: the same in Python, in JSON
# Schema (ECMA-262) and in a browser's ``pattern``.

_SEP: Final = "[ ,]"
"""What separates the numbers of a text option: spaces or commas (the parsers' rule)."""


def _decimal_at_most(integer_digits: int, maximum: str) -> str:
    """Return a pattern of a signed plain decimal whose magnitude is at most ``maximum``.

    ``integer_digits`` digits before the point stay below ``maximum``, which is then
    allowed as itself (``1000``, ``1000.000``). No exponent: a pattern cannot bound it.
    """
    return rf"[+\-]?0*([0-9]{{1,{integer_digits}}}(\.[0-9]*)?|\.[0-9]+|{maximum}(\.0*)?)"


_ANY_DECIMAL: Final = r"[+\-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)"
_POSITIVE: Final = r"\+?([0-9]*[1-9][0-9]*(\.[0-9]*)?|[0-9]*\.[0-9]*[1-9][0-9]*)"
"""A plain decimal above zero (at least one digit that is not 0)."""
_PERCENT: Final = r"\+?0*([1-9][0-9]?(\.[0-9]*)?|\.[0-9]*[1-9][0-9]*|100(\.0*)?)"
"""A plain decimal above 0 and at most 100."""
_OFFSET_M: Final = _decimal_at_most(3, "1000")  # MAX_OFFSET_M
_COORDINATE_M: Final = _decimal_at_most(9, "1000000000")  # MAX_COORDINATE_M
_YAW_DEG: Final = r"[+\-]?0*(([0-9]{1,2}|[12][0-9]{2}|3[0-5][0-9])(\.[0-9]*)?|\.[0-9]+|360(\.0*)?)"


def _numbers(*items: str) -> str:
    """Return the pattern of numbers separated by spaces or commas (leading, trailing too)."""
    return f"{_SEP}*" + f"{_SEP}+".join(f"({item})" for item in items) + f"{_SEP}*"


_XYZ: Final = _numbers(_OFFSET_M, _OFFSET_M, _OFFSET_M)
OFFSET_PATTERN: Final = (
    f"^({_numbers(_OFFSET_M, _OFFSET_M, _OFFSET_M)}"
    f"|{_numbers(_OFFSET_M, _OFFSET_M, _OFFSET_M, *[_ANY_DECIMAL] * 4)})?$"
)
SITE_PATTERN: Final = (
    f"^({_numbers(*[_COORDINATE_M] * 3)}|{_numbers(*[_COORDINATE_M] * 3, _YAW_DEG)})?$"
)
TAG_OFFSET_PATTERN: Final = f"^( *|{_XYZ})$"
TOLERANCE_PATTERN: Final = f"^ *({_POSITIVE}) *m? *(@ *({_PERCENT}) *%?)? *$"
_SECONDS: Final = r"0*([1-9][0-9]{0,8}(\.[0-9]*)?|0?\.[0-9]*[1-9][0-9]*|1000000000(\.0*)?)"
"""A plain decimal of seconds above 0 and at most MAX_SPAN_S (1e9)."""
ALIGN_FIRST_PATTERN: Final = rf"^( *(0*[1-9][0-9]*|{_SECONDS} *s) *)?$"
CRS_PATTERN: Final = r"^[A-Za-z][A-Za-z0-9_.\-]*:[A-Za-z0-9_.\-]+$"
"""AUTHORITY:CODE, e.g. EPSG:25832 (the exporters' own check, spelled the same)."""


TRIAL_OPTIONS: Final[tuple[OptionSpec, ...]] = (
    OptionSpec(
        "baseline",
        OptionKind.FILE,
        None,
        "an earlier result to compare each estimate and system with, by name: a result.json "
        "(errors.csv beside it pairs the errors), the folder an earlier evaluation wrote, an "
        "evo result zip or a folder of them (the API: the id of a succeeded evaluation)",
        "the baseline",
        "baseline",
        "PATH",
        max_length=500,
        group="baseline",
        label="Baseline",
    ),
    OptionSpec(
        "min_trial_coverage",
        OptionKind.NUMBER,
        0.5,
        "trials (estimates of a named system): the least share of the reference's duration "
        "a trial must track; a trial tracking less failed (tracking lost) and is counted, "
        "not averaged",
        "the least trial coverage",
        "min-trial-coverage",
        "SHARE",
        minimum=0.0,
        maximum=1.0,
        label="Least trial coverage",
    ),
)
"""The rows of :data:`loceval.options.OPTIONS` about trials and the baseline (issue 41).

The table splices them in at their place; they are written here, beside the specification,
because the table's module is at the length every module keeps to.
"""


GATE_OPTIONS: Final[tuple[OptionSpec, ...]] = (
    OptionSpec(
        "fail_on",
        OptionKind.NAMES,
        None,
        "the gate: exit 3 (the API: gate.passed false) when an estimate's tolerance verdict "
        "is fail or undecided, or it is worse than the baseline; any of fail, undecided, "
        "worse, comma-separated or repeated",
        "the gate's conditions",
        "fail-on",
        "fail,undecided,worse",
        choices=("fail", "undecided", "worse"),
        min_length=1,
        max_length=3,
        group="export",
        label="Fail on",
    ),
)
"""The gate's option (issue 41), in :data:`loceval.options.OPTIONS` after the tolerance whose
verdict it judges; kept here, beside the trials' options, so the table stays one screenful."""


RANGING_OPTIONS: Final[tuple[OptionSpec, ...]] = (
    OptionSpec(
        "solve",
        OptionKind.NAMES,
        ("nlls", "minmax"),
        "ranging: the positioning algorithms run on the ranges (nlls, minmax)",
        "the positioning algorithms",
        "solve",
        "NAME,...",
        choices=("nlls", "minmax"),
        min_length=1,
        max_length=2,
        group="ranging",
        label="Positioning algorithms",
    ),
    OptionSpec(
        "dims",
        OptionKind.CHOICE,
        "2",
        "ranging: position in 2D (tag at a fixed height) or 3D",
        "the number of dimensions",
        "dims",
        choices=("2", "3"),
        group="ranging",
        label="Dimensions",
    ),
    OptionSpec(
        "epoch_s",
        OptionKind.NUMBER,
        0.1,
        "ranging: the length of a positioning epoch, seconds",
        "the epoch length",
        "epoch",
        "S",
        minimum=0.0,
        maximum=3600.0,
        exclusive_minimum=True,
        group="ranging",
        label="Epoch (s)",
    ),
    OptionSpec(
        "tag_height_m",
        OptionKind.NUMBER,
        None,
        "ranging, 2D: the tag's fixed height, metres (default: the reference's median)",
        "the tag height",
        "tag-height",
        "H",
        minimum=-1e4,
        maximum=1e4,
        group="ranging",
        label="Tag height (m)",
    ),
    OptionSpec(
        "tag_offset_xyz",
        OptionKind.TEXT,
        None,
        'ranging: the tag in the reference body frame "x y z", metres',
        "the tag offset",
        "tag-offset",
        '"x y z"',
        max_length=100,
        pattern=TAG_OFFSET_PATTERN,
        example="0 0 0.3",
        group="ranging",
        label="Tag offset (m)",
    ),
    OptionSpec(
        "outlier_threshold_m",
        OptionKind.NUMBER,
        1.0,
        "ranging: the |error| beyond which a range is an outlier, metres",
        "the outlier threshold",
        "outlier-threshold",
        "M",
        minimum=0.0,
        maximum=1e4,
        exclusive_minimum=True,
        group="ranging",
        label="Outlier threshold (m)",
    ),
    OptionSpec(
        "distance_bin_m",
        OptionKind.NUMBER,
        2.0,
        "ranging: the width of the error-versus-distance bins, metres",
        "the distance bin width",
        "distance-bin",
        "M",
        minimum=0.0,
        maximum=1e4,
        exclusive_minimum=True,
        group="ranging",
        label="Distance bin (m)",
    ),
)
"""The radio-ranging options (``loceval ranging``, ``POST /ranging``), last in the table."""
