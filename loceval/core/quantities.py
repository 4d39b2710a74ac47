"""How a quantity is written for a person: one set of symbols, one uncertainty, one duration.

Issue 44 found "9.4 +/- 0.3 ms" beside "-9.39 ± 0.34 ms", "<=" and "->" in the viewer and
"gaps longer than 0.16089 s". Every sentence, table and label writes:

- the symbols :data:`PLUS_MINUS` (±), :data:`AT_MOST` (≤) and :data:`ARROW` (→, and
  :data:`ARROW_BACK` ← for an inverted tf link); reports,
  PDFs, the viewer and CAD files show them, and the command line spells them in ASCII
  (:data:`ASCII_SPELLINGS`) only on a terminal whose encoding lacks them;
- a value with its uncertainty through :func:`plus_minus` (``"9.4 ± 0.3 ms"``): the
  value to the places of its sigma's significant digits (:func:`decimals_for`);
- a duration through :func:`format_duration` (``"161 ms"``, ``"12.3 s"``, ``"3 s"``,
  ``"4540 s"``): three significant digits at most, milliseconds under a second.
"""

from __future__ import annotations

import math
from typing import Final

__all__ = [
    "ARROW",
    "ARROW_BACK",
    "ASCII_SPELLINGS",
    "AT_MOST",
    "PLUS_MINUS",
    "decimals_for",
    "format_duration",
    "plus_minus",
    "signed_difference",
]

PLUS_MINUS: Final = "±"
AT_MOST: Final = "≤"
ARROW: Final = "→"
ARROW_BACK: Final = "←"

ASCII_SPELLINGS: Final[dict[str, str]] = {
    PLUS_MINUS: "+/-",
    AT_MOST: "<=",
    ARROW: "->",
    ARROW_BACK: "<-",
}
"""How a terminal that cannot show a symbol spells it."""

_MAX_DECIMALS: Final = 6


_TWO_DIGITS_BELOW: Final = 3.55
"""A sigma whose leading digits are below this keeps two significant digits, else one
(the Particle Data Group's rounding rule: 0.34 stays 0.34, 0.7 is not written 0.70)."""


def decimals_for(sigma: float) -> int:
    """Return the decimal places of a value whose 1-sigma is ``sigma`` (0 to 6).

    Two significant digits of sigma when they start with 1 to 3.5, one otherwise
    (:data:`_TWO_DIGITS_BELOW`).
    """
    if not math.isfinite(sigma) or sigma <= 0:
        return 2
    power = math.floor(math.log10(sigma))
    significant = 2 if sigma / 10.0**power < _TWO_DIGITS_BELOW else 1
    return max(0, min(_MAX_DECIMALS, significant - 1 - power))


def plus_minus(
    value: float, sigma: float | None, unit: str = "", *, sign: bool = False, places: int = 1
) -> str:
    """Return ``"9.4 ± 0.3 ms"``: a value and its 1-sigma, both to sigma's places.

    Args:
        value: the value, in ``unit``.
        sigma: its standard uncertainty in ``unit``; None writes the value alone.
        unit: the unit written after both ("ms", "ppm"); empty for none.
        sign: write the value's sign even when positive (``+9.4``).
        places: decimal places of a value without sigma (or with sigma 0).
    """
    decimals = places if sigma is None or sigma <= 0 else decimals_for(sigma)
    number = f"{value:+.{decimals}f}" if sign else f"{value:.{decimals}f}"
    text = number if sigma is None else f"{number} {PLUS_MINUS} {sigma:.{decimals}f}"
    return f"{text} {unit}" if unit else text


def format_duration(seconds: float) -> str:
    """Return a duration to three significant digits: ``"161 ms"``, ``"1.5 s"``, ``"4540 s"``.

    Milliseconds under a second; whole seconds from 100 s on (no "4.54e+03 s").
    """
    if not math.isfinite(seconds):
        return f"{seconds} s"
    size = abs(seconds)
    if size == 0:
        return "0 s"
    if size < 1.0:
        ms = _three_digits(seconds * 1e3)
        if abs(float(ms)) < 1000:  # 0.9996 s is "1.00 s", not "1000 ms"
            return f"{ms} ms"
        size = seconds = math.copysign(1.0, seconds)
    if size >= 100.0:
        return f"{seconds:.0f} s"
    return f"{_three_digits(seconds)} s"


def signed_difference(value: float, unit: str) -> str:
    """Return a signed difference: lengths under a metre in cm (``"+1.9 cm"``), else ``unit``.

    ``unit`` is ``"m"``, ``"deg"`` (written ``°``) or any other unit, written after a space.
    """
    if unit == "m" and abs(value) < 1.0:
        return f"{value * 100:+.1f} cm"
    if unit == "m":
        return f"{value:+.3f} m"
    return f"{value:+.3g}{'°' if unit == 'deg' else ' ' + unit}"


def _three_digits(value: float) -> str:
    """Three significant digits in fixed notation, no trailing zero (161.2 -> ``161``, 3 -> ``3``).

    0.00161 -> ``0.00161``, 12.34 -> ``12.3``, 1.50 -> ``1.5``, 9.996 -> ``10``.
    """
    decimals = max(0, 2 - math.floor(math.log10(abs(value))))
    text = f"{value:.{decimals}f}"
    if float(text) != 0 and abs(float(text)) >= 10 ** (3 - decimals):  # 9.996 -> "10.00"
        text = f"{value:.{max(0, decimals - 1)}f}"
    return text.rstrip("0").rstrip(".") if "." in text else text
