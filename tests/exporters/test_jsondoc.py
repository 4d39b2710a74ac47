"""The JSON writer refuses NaN and infinity, naming where, instead of writing invalid JSON."""

from __future__ import annotations

import json
import math

import pytest

from exporters.cad.jsondoc import finite_json
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
