"""The figure kit (exporters.plots.svg): text widths, ticks, path data, layout and the SVG.

The kit draws the report's figures without matplotlib; what it measures and writes is
checked here against independent computations: the glyph widths against the font files
(fontTools) and against matplotlib's own text measure (FreeType), the paths against the
points they were given, and the documents with an XML parser.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from exporters.plots.svg import _glyph_widths
from exporters.plots.svg.canvas import ColourBar, Figure
from exporters.plots.svg.draw import (
    UNIT,
    Style,
    marker_path,
    path_data,
    polygon_data,
    segment_data,
    svg_text,
)
from exporters.plots.svg.metrics import text_width_pt
from exporters.plots.svg.ticks import MINUS, format_ticks, nice_ticks, padded_limits
from exporters.plots.svg.widths_table import generated_table

SVG = "{http://www.w3.org/2000/svg}"


def _pairs(data: str) -> list[list[tuple[int, int]]]:
    """The pieces of path data as lists of integer points (each piece starts with M)."""
    pieces = []
    for piece in re.findall(r"M[^M]*", data):
        numbers = [int(v) for v in re.findall(r"-?\d+", piece)]
        pieces.append(list(zip(numbers[::2], numbers[1::2], strict=True)))
    return pieces


def test_the_width_table_is_the_fonts() -> None:
    """The tabled widths are those of matplotlib's DejaVu files (regenerate on a change)."""
    pytest.importorskip("fontTools")
    assert Path(_glyph_widths.__file__).read_text(encoding="utf-8") == generated_table()


@pytest.mark.parametrize(
    "text",
    ["ATE [m]", "time since the start of the reference [s]", "−0.25", "poses with error ≤ x [%]"],
)
def test_widths_agree_with_matplotlibs_measure(text: str) -> None:
    """Within 3 % of matplotlib's FreeType measure of the same string at 10 pt (kerning)."""
    font_manager = pytest.importorskip("matplotlib.font_manager")
    textpath = pytest.importorskip("matplotlib.textpath")
    prop = font_manager.FontProperties(family="DejaVu Sans", size=10)
    width, _, _ = textpath.TextToPath().get_text_width_height_descent(text, prop, ismath=False)
    assert text_width_pt(text, 10.0) == pytest.approx(width, rel=0.03)


def test_an_unknown_character_is_as_wide_as_an_m() -> None:
    """A character outside the table (CJK) is measured as an M: wide, never zero."""
    assert text_width_pt("測", 10.0) == text_width_pt("M", 10.0) > 0


@pytest.mark.parametrize(
    ("lo", "hi", "count", "ticks", "labels"),
    [
        (0.0, 1.0, 6, [0.0, 0.2, 0.4, 0.6, 0.8, 1.0], ["0.0", "0.2", "0.4", "0.6", "0.8", "1.0"]),
        (-0.8, 3.4, 10, [-0.5, 0, 0.5, 1, 1.5, 2, 2.5, 3], None),
        (
            0.0,
            0.021,
            6,
            [0, 0.005, 0.01, 0.015, 0.02],
            ["0.000", "0.005", "0.010", "0.015", "0.020"],
        ),
        (-37.0, 61.0, 6, [-20, 0, 20, 40, 60], [f"{MINUS}20", "0", "20", "40", "60"]),
        (0.0, 0.15, 8, [0, 0.025, 0.05, 0.075, 0.1, 0.125, 0.15], None),
    ],
)
def test_ticks_are_round_and_labelled_alike(
    lo: float, hi: float, count: int, ticks: list[float], labels: list[str] | None
) -> None:
    """Steps of 1, 2, 2.5 or 5 times a power of ten; every label with the step's decimals."""
    values, step = nice_ticks(lo, hi, count)
    np.testing.assert_allclose(values, ticks, atol=1e-12)
    assert len(values) <= count
    if labels is not None:
        assert format_ticks(values, step) == labels


def test_limits_pad_the_data_and_survive_one_value() -> None:
    """5 % of the span beyond the data; a single value gets a span of its own."""
    assert padded_limits(0.0, 10.0) == pytest.approx((-0.5, 10.5))
    assert padded_limits(3.0, 3.0) == pytest.approx((2.85, 3.15))
    assert padded_limits(0.0, 0.0) == pytest.approx((-0.05, 0.05))
    assert padded_limits(0.0, 1e-14) == pytest.approx((-5e-16, 1.05e-14))  # noise stays small
    assert padded_limits(float("inf"), -float("inf")) == (0.0, 1.0)


def test_a_line_breaks_at_nan_and_keeps_every_vertex() -> None:
    """Every finite point is a vertex; NaN starts a new piece; a lone point draws nothing."""
    points = np.array(
        [[0, 0], [1, 1], [np.nan, np.nan], [2, 2], [3, 3], [4, 4], [np.nan, 0], [5, 5]], float
    )
    pieces = _pairs(path_data(points))
    assert pieces == [[(0, 0), (100, 100)], [(200, 200), (300, 300), (400, 400)]]


def test_touching_segments_are_one_line() -> None:
    """Segments that meet are written as one piece; a segment apart starts another."""
    segments = np.array([[[0, 0], [1, 1]], [[1, 1], [2, 0]], [[5, 5], [6, 6]]], float)
    assert _pairs(segment_data(segments)) == [
        [(0, 0), (100, 100), (200, 0)],
        [(500, 500), (600, 600)],
    ]


def test_a_band_is_closed_over_each_run() -> None:
    """The band goes along the upper edge and back along the lower one, once per run."""
    upper = np.array([[0, 1], [1, 1], [2, 1], [3, 1]], float)
    lower = upper - [0, 1]
    data = polygon_data(upper, lower, np.array([True, True, False, True]))
    assert data.count("Z") == 1  # the run of one point has no area
    assert _pairs(data) == [[(0, 100), (100, 100), (100, 0), (0, 0)]]


def test_markers_are_circles_round_each_point() -> None:
    """Each marker is two arcs of its radius, starting at its left end."""
    data = marker_path(np.array([[1.0, 2.0], [3.0, 4.0]]), "o", 4.0)
    assert data.count("M") == 2
    assert data.startswith(f"M{1 * UNIT - 2 * UNIT} {2 * UNIT}a{2 * UNIT} {2 * UNIT} 0 1 0")


def test_text_is_escaped_and_measured() -> None:
    """A text's characters are escaped; its box is its measured width."""
    boxes: list = []
    element = svg_text("a < b & c", 10.0, 20.0, size_pt=8.0, anchor="start", boxes=boxes)
    assert ET.fromstring(element).text == "a < b & c"  # noqa: S314  (our own SVG)
    assert boxes[0].width == pytest.approx(text_width_pt("a < b & c", 8.0))
    assert boxes[0].left == pytest.approx(10.0)


def _figure() -> Figure:
    fig = Figure(height_in=4.0)
    (ax,) = fig.subplots()
    t = np.linspace(0.0, 10.0, 50)
    ax.line(t, np.sin(t), Style(colour="#ff0000"), label="sine")
    ax.line(t, 2 * np.cos(t), Style(colour="#0000ff", dash="dashed"), label="cosine")
    ax.xlabel, ax.ylabel = "t [s]", "value & more"
    fig.legend_above(ax)
    return fig


def test_the_figure_is_a_well_formed_svg_of_its_size() -> None:
    """An XML document 7 in wide (points), its texts as text, its lines as paths."""
    fig = _figure()
    root = ET.fromstring(fig.svg())  # noqa: S314  (our own SVG)
    assert root.get("width") == "504pt"
    assert root.get("viewBox") == f"0 0 {504 * UNIT} {round(288 * UNIT)}"
    texts = [t.text for t in root.iter(f"{SVG}text")]
    assert {"t [s]", "value & more", "sine", "cosine"} <= set(texts)
    strokes = {p.get("stroke") for p in root.iter(f"{SVG}path")}
    assert {"#ff0000", "#0000ff"} <= strokes


def test_the_layout_keeps_every_text_on_the_figure_and_off_the_plot() -> None:
    """Each drawn text lies on the page, and none but the plot's own on its plotting area."""
    fig = _figure()
    fig.svg()
    box = fig.axes[0].box
    for owner, boxes in fig.text_boxes.items():
        for text in boxes:
            assert text.left >= -0.5
            assert text.top >= -0.5
            assert text.right <= fig.width_pt + 0.5
            assert text.bottom <= fig.height_pt + 0.5
            if owner == "legend":
                assert text.bottom <= box.top
    assert box.left > 20
    assert box.bottom < fig.height_pt - 20


def test_an_equal_aspect_plot_draws_a_metre_alike_both_ways() -> None:
    """A plan view widens one axis so x and y have the same points per metre."""
    fig = Figure(height_in=4.0)
    (ax,) = fig.subplots()
    ax.line(np.array([0.0, 10.0]), np.array([0.0, 1.0]), Style())
    ax.equal = True
    fig.svg()
    (x0, x1), (y0, y1) = ax.view_x, ax.view_y
    assert ax.box.width / (x1 - x0) == pytest.approx(ax.box.height / (y1 - y0))
    assert x0 <= 0.0
    assert x1 >= 10.0
    assert y0 <= 0.0
    assert y1 >= 1.0


def test_a_colour_bar_places_values_in_equal_bins() -> None:
    """Each bin takes the same height; a value inside one is placed linearly in it."""
    bar = ColourBar([0.0, 0.01, 0.02, 0.1], ["#00ff00", "#ffff00", "#ff0000"], "ATE [m]")
    assert bar.position(0.0) == 0.0
    assert bar.position(0.01) == pytest.approx(1 / 3)
    assert bar.position(0.015) == pytest.approx(0.5)
    assert bar.position(0.1) == pytest.approx(1.0)


def test_shared_x_labels_only_the_lowest_plot() -> None:
    """Plots sharing x show one axis' labels, under the lowest, and one range."""
    fig = Figure(height_in=4.0)
    top, bottom = fig.subplots(2, sharex=True)
    top.line(np.array([0.0, 5.0]), np.array([0.0, 1.0]), Style())
    bottom.line(np.array([2.0, 9.0]), np.array([0.0, 1.0]), Style())
    fig.svg()
    assert top.view_x == bottom.view_x
    assert top.view_x[0] <= 0.0
    assert top.view_x[1] >= 9.0
    assert not top.show_xticklabels
    assert bottom.show_xticklabels
    assert top.box.bottom < bottom.box.top


def test_a_long_name_is_cut_to_the_legends_width() -> None:
    """An estimate named at length ends in an ellipsis; the legend stays on the figure."""
    fig = Figure(height_in=3.0)
    (ax,) = fig.subplots()
    name = "a very long estimate name from a site team's bag file " * 4
    ax.line(np.array([0.0, 1.0]), np.array([0.0, 1.0]), Style(), label=name)
    fig.legend_above(ax)
    root = ET.fromstring(fig.svg())  # noqa: S314  (our own SVG)
    (label,) = [t.text for t in root.iter(f"{SVG}text") if t.text and t.text.startswith("a very")]
    assert label.endswith("…")
    assert name.startswith(label[:-1])
    assert all(box.right <= fig.width_pt for box in fig.text_boxes["legend"])
