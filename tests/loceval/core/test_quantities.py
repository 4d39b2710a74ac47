"""One set of symbols, one value-with-uncertainty and one duration formatter (issue 44, 10, 16)."""

from __future__ import annotations

import pytest

from loceval.core.quantities import (
    ARROW,
    ASCII_SPELLINGS,
    AT_MOST,
    PLUS_MINUS,
    decimals_for,
    format_duration,
    plus_minus,
)


@pytest.mark.parametrize(
    ("seconds", "shown"),
    [
        (0.16089, "161 ms"),  # the "gaps longer than 0.16089 s"
        (0.1, "100 ms"),
        (0.0005, "0.5 ms"),
        (0.9996, "1 s"),  # rounds up to a second: not "1000 ms"
        (1.0, "1 s"),
        (1.5, "1.5 s"),
        (12.345, "12.3 s"),
        (11.987, "12 s"),
        (99.96, "100 s"),
        (4540.0, "4540 s"),
        (-0.25, "-250 ms"),
        (0.0, "0 s"),
    ],
)
def test_durations_have_three_significant_digits(seconds: float, shown: str) -> None:
    """Milliseconds under a second, three significant digits at most (no trailing zero)."""
    assert format_duration(seconds) == shown


@pytest.mark.parametrize(
    ("value", "sigma", "unit", "shown"),
    [
        (9.4123, 0.4, "ms", "9.4 ± 0.4 ms"),  # one digit of a sigma from 3.55 up ...
        (-9.3912, 0.34, "ms", "-9.39 ± 0.34 ms"),  # ... two below it
        (294.2, 8.0, "ppm", "294 ± 8 ppm"),
        (45.2, None, "ms", "45.2 ms"),
        (3.0, 0.0, "", "3.0 ± 0.0"),
    ],
)
def test_a_value_with_its_sigma(value: float, sigma: float | None, unit: str, shown: str) -> None:
    """The value to its sigma's places, "±" between them, the unit once after both."""
    assert plus_minus(value, sigma, unit) == shown


def test_a_signed_value() -> None:
    """``sign=True`` writes "+" on a positive value (the clock table's offsets and rates)."""
    assert plus_minus(50.0213, 0.031, "ppm", sign=True) == "+50.021 ± 0.031 ppm"


def test_decimals_follow_the_sigma() -> None:
    """0.34 keeps two digits (2 places), 0.7 one (1 place), 12 none; no sigma: 2 places."""
    assert [decimals_for(s) for s in (0.34, 0.7, 12.0, 0.0)] == [2, 1, 0, 2]


def test_the_symbols_and_their_ascii_spellings() -> None:
    """One Unicode set; the ASCII spellings are what a terminal without it shows."""
    assert (PLUS_MINUS, AT_MOST, ARROW) == ("±", "≤", "→")
    assert ASCII_SPELLINGS[PLUS_MINUS] == "+/-"
    assert ASCII_SPELLINGS[AT_MOST] == "<="
    assert ASCII_SPELLINGS[ARROW] == "->"
