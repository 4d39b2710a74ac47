"""The patterns the API's schema declares for text options take only what the parsers take.

Each pattern of the options table is the API's grammar of its option: the schema declares
it and the service holds requests to it (after the option's parser, whose messages say
more). Every text a pattern admits must then be taken by the parser, or the schema would
call a request valid that the server refuses.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from exporters.cad.site import parse_site
from exporters.options import ExportOptions
from loceval.assessment.verdict import Tolerance
from loceval.errors import InputError, LocevalError
from loceval.options import OPTIONS, OptionKind, option
from loceval.radio_evaluation import parse_tag_offset
from loceval.registration.alignment import AlignWindow
from service.jobs.options import check_pattern, offset_or_none


def _site(text: str) -> object:
    return parse_site(text) if text else None


PARSERS: dict[str, Callable[[str], object]] = {
    "align_first": AlignWindow.parse,
    "offset": offset_or_none,
    "tolerance": Tolerance.parse,
    "site": _site,
    "crs": lambda text: ExportOptions(crs=text),
    "tag_offset_xyz": parse_tag_offset,
}
"""The parser the service runs on each option that has a pattern."""


def test_every_pattern_has_its_parser_here() -> None:
    """A pattern added to the table is tested below (add its parser to PARSERS)."""
    assert {s.key for s in OPTIONS if s.pattern is not None} == PARSERS.keys()


@pytest.mark.parametrize("key", sorted(PARSERS))
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_what_the_pattern_admits_the_parser_takes(key: str, data: st.DataObject) -> None:
    """Texts generated from the pattern parse (bounds, unit quaternion aside: see below)."""
    spec = option(key)
    assert spec.pattern is not None
    text = data.draw(
        st.from_regex(spec.pattern, fullmatch=True).filter(
            lambda t: len(t) <= (spec.max_length or 500)
        )
    )
    if key == "offset":
        text = _unit_quaternion(text)
    PARSERS[key](text)
    check_pattern(key, text)


def _unit_quaternion(text: str) -> str:
    """Replace the quaternion of a 7-number offset by a unit one (a pattern cannot say unit)."""
    numbers = text.replace(",", " ").split()
    return " ".join([*numbers[:3], "0", "0", "0", "1"]) if len(numbers) == 7 else text


@pytest.mark.parametrize(
    ("key", "text", "parser_message"),
    [
        ("tolerance", "1e-1@95", None),
        ("tolerance", "0.10 @ 9.5e1", None),
        ("tolerance", "abc", r"takes METRES@PERCENT"),
        ("tolerance", "0.1@200", r"share must be in \(0, 100\] percent"),
        ("offset", "1e2 0 0", None),
        ("offset", "0\t0\t0", None),
        ("offset", "1 2", r'takes "x y z qx qy qz qw"'),
        ("offset", "0 1e308 0", r"exceed ±1000 m"),
        ("site", "1_000 0 0", None),
        ("site", "0 0 0 1e300", r"yaw must be within ±360 degrees"),
        ("tag_offset_xyz", "\u0661 0 0", None),
        ("align_first", "1e1s", None),
        ("align_first", "ten", r"takes a number of poses or seconds"),
    ],
)
def test_parser_first_then_pattern(key: str, text: str, parser_message: str | None) -> None:
    """A malformed text gets its parser's message; what the parser forgives, the pattern refuses."""
    if parser_message is not None:
        with pytest.raises(LocevalError, match=parser_message):
            PARSERS[key](text)
    else:
        PARSERS[key](text)  # the core (and the CLI) take it
    with pytest.raises(InputError, match=r"must read .* got") as caught:
        check_pattern(key, text)
    assert caught.value.option == key


def test_only_text_options_have_patterns() -> None:
    """The API declares patterns on texts only (numbers have bounds, choices an enum)."""
    assert all(s.kind is OptionKind.TEXT for s in OPTIONS if s.pattern is not None)
