"""The grammars of the text options, as regular expressions the HTTP API declares and checks.

Each accepts a subset of what the option's parser takes (plain decimals, no exponent, with
the option's bounds spelled out in digits), so that the API's schema can say exactly which
texts the server takes: a pattern cannot bound ``1e3`` but can bound ``1000``. The CLI
keeps the parsers' wider forms. Patterns use only ASCII classes, groups and counts, so
they mean the same in Python, in JSON Schema (ECMA-262) and in a browser's ``pattern``.
"""

from __future__ import annotations

from typing import Final

__all__ = [
    "ALIGN_FIRST_PATTERN",
    "CRS_PATTERN",
    "OFFSET_PATTERN",
    "SITE_PATTERN",
    "TAG_OFFSET_PATTERN",
    "TOLERANCE_PATTERN",
]

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
