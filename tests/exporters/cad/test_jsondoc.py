"""The JSON writer refuses NaN and infinity, naming where, instead of writing invalid JSON."""

from __future__ import annotations

import json
import math

import pytest

from exporters.cad.jsondoc import JSONItems, finite_json
from exporters.errors import ExportError


def test_finite_documents_are_written() -> None:
    """A document of finite numbers round-trips."""
    document = {"a": [1.0, 2, {"b": -3.5e300}], "c": None, "d": "text"}
    assert json.loads(finite_json(document)) == document


@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan])
def test_non_finite_numbers_are_refused_with_their_place(value: float) -> None:
    """inf or NaN anywhere is an ExportError naming its path (was a ValueError: exit 2)."""
    document = {"stats": [{"rmse": 1.0}, {"rmse": value}]}
    where = r"\$\.stats\[1\]\.rmse"
    with pytest.raises(ExportError, match=rf"The result holds .* at {where}, a number JSON"):
        finite_json(document)


def test_layered_documents_round_trip_with_their_outer_levels_on_lines() -> None:
    """``levels`` lays out the outer containers over lines and writes deeper ones compactly."""
    document = {
        "format": "x",
        "base_point": [1.0, 2.0, 3.0],
        "paths": [{"name": "a", "ate": [{"bin": 0, "curve": {"data": "AA=="}}, {"bin": 1}]}],
        "empty": [],
    }
    text = finite_json(document, indent=1, levels=3)
    assert json.loads(text) == document
    assert text.splitlines() == [
        "{",
        ' "format": "x",',
        ' "base_point": [1.0, 2.0, 3.0],',  # holds no container: one line at any level
        ' "paths": [',
        "  {",
        '   "name": "a",',
        '   "ate": [{"bin": 0, "curve": {"data": "AA=="}}, {"bin": 1}]',  # the fourth level
        "  }",
        " ],",
        ' "empty": []',
        "}",
    ]


def test_layered_documents_refuse_non_finite_numbers_deep_down() -> None:
    """A NaN below the laid-out levels is refused with its place, as without ``levels``."""
    document = {"paths": [{"ate": [{"curve": {"x": [0.0, math.nan]}}]}]}
    with pytest.raises(ExportError, match=r"at \$\.paths\[0\]\.ate\[0\]\.curve\.x\[1\]"):
        finite_json(document, indent=1, levels=2)


@pytest.mark.parametrize("levels", [0, 1, 2, 3, 4])
def test_encoded_items_are_placed_as_the_containers_they_encode(levels: int) -> None:
    """JSONItems give the text their list of containers gives, at any level."""
    ate = [{"bin": 0, "curve": {"data": "AA=="}}, {"bin": 1}]
    document = {
        "paths": [
            {"name": "a", "ate": ate},
            {"name": "b", "ate": [], "pair": [{"x": [ate, 2]}, 3]},
        ],
    }
    encoded = {
        "paths": [
            {"name": "a", "ate": JSONItems(json.dumps(item) for item in ate)},
            {
                "name": "b",
                "ate": JSONItems(),
                "pair": [{"x": [JSONItems(map(json.dumps, ate)), 2]}, 3],
            },
        ],
    }
    expected = finite_json(document, indent=1, levels=levels)
    assert finite_json(encoded, indent=1, levels=levels) == expected
