"""Report wording: the length unit chosen per table, the alignment window, CDF labels."""

from __future__ import annotations

import pytest

from exporters.plots.series import _label_thresholds
from exporters.plots.svg.canvas import Figure
from exporters.report.provenance import _window
from exporters.report.view import MM_BELOW_M, length_unit
from loceval.registration.alignment import AlignWindow


@pytest.mark.parametrize(
    ("values_m", "symbol", "text"),
    [
        ([0.0061, 0.0213, 0.0002], "mm", "6.1"),  # fr2_desk ORB's ATE RMSE: 0.006 m before
        ([0.0299, 0.0843, 0.001], "mm", "29.9"),  # nav2 AMCL: largest 0.084 m
        ([0.05, 0.1, 0.0], "m", "0.050"),  # the largest is 0.1 m: metres
        ([3.2, 12.5], "m", "3.200"),
        ([], "m", "0.000"),
    ],
)
def test_length_unit_per_table(values_m: list[float], symbol: str, text: str) -> None:
    """Millimetres when every value is below 0.1 m, with one decimal; else metres."""
    unit = length_unit(values_m)
    assert MM_BELOW_M == 0.1
    assert unit.symbol == symbol
    assert unit.format(values_m[0] if values_m else 0.0) == text


@pytest.mark.parametrize(
    ("text", "words"),
    [
        (None, "all poses"),
        ("1", "the first pose"),
        ("1500", "the first 1,500 poses"),
        ("5s", "the first 5 s"),
    ],
)
def test_alignment_window_in_words(text: str | None, words: str) -> None:
    """'1 poses' and '5s poses' read as 'the first pose' and 'the first 5 s'."""
    assert _window(AlignWindow.parse(text)) == words


def test_threshold_labels_never_overlap() -> None:
    """On a 0-20 m axis, 0.05/0.1/0.15 m stack on rows; a fourth close one is left out."""
    (ax,) = Figure(height_in=4.0).subplots()
    ax.set_xlim(0.0, 20.0)
    _label_thresholds(ax, [0.05, 0.1, 0.15, 0.2, 10.0])
    # each row 9 points above the one below it (the labels are 7 points high)
    placed = [(t.string, t.offset_pt[1]) for t in ax.texts]
    assert placed == [("0.05 m", 2.0), ("0.1 m", 11.0), ("0.15 m", 20.0), ("10 m", 2.0)]
