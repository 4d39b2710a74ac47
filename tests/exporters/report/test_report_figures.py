"""The report's figures: drawn once for both reports, PNG opaque at print resolution."""

from __future__ import annotations

import base64
import hashlib
import io
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.layout_engine import ConstrainedLayoutEngine
from PIL import Image

from exporters import write_artifacts
from exporters.options import ExportOptions
from exporters.plots import figure as figure_module
from exporters.plots.figure import PNG_DPI, WIDTH_IN
from exporters.report import render_report_html, render_report_plots
from exporters.report.provenance import yaw_pitch_roll_deg
from loceval.core.rotation import Rotation
from loceval.evaluation import EvaluationResult

_SVG_ID = re.compile(rb'(?<=id=")(?:image|[a-z])[0-9a-f]{10}(?=")|(?<=#)[a-z][0-9a-f]{10}(?=[")])')
"""matplotlib's random or data-derived element ids (``id="p1a2b3c4d5e"``, ``url(#p...)``,
``href="#m..."``, ``id="image0123456789"``)."""


_SVG_PNG = re.compile(rb"data:image/png;base64,([A-Za-z0-9+/=\n]+)")


def _pixels(match: re.Match[bytes]) -> bytes:
    """An embedded bitmap as the digest of its pixels (its zlib stream varies run to run)."""
    image = Image.open(io.BytesIO(base64.b64decode(match.group(1).replace(b"\n", b""))))
    digest = hashlib.sha256(image.tobytes() + repr(image.size).encode()).hexdigest()
    return b"pixels:" + digest.encode()


def _numbered_ids(svg: bytes) -> bytes:
    """The SVG with its element ids numbered in order of first appearance."""
    names: dict[bytes, bytes] = {}
    return _SVG_ID.sub(lambda m: names.setdefault(m.group(0), b"id%d" % len(names)), svg)


def _figures(html: bytes) -> list[bytes]:
    """The report's SVG figures, matplotlib's random ids numbered, bitmaps as pixel digests."""
    return [
        _numbered_ids(_SVG_PNG.sub(_pixels, base64.b64decode(uri)))
        for uri in re.findall(rb"data:image/svg\+xml;base64,([A-Za-z0-9+/=]+)", html)
    ]


def test_both_reports_from_one_drawing_match_each_alone(
    two_estimates: EvaluationResult, tmp_path: Path
) -> None:
    """report.html written beside report.pdf has the figures of report.html written alone."""
    options = ExportOptions(title="Shared figures", evaluation_id="ev-shared")
    seen: list[tuple[str, bytes]] = []
    written = write_artifacts(
        two_estimates,
        tmp_path / "out",
        options,
        names=["report.html", "report.pdf"],
        on_written=lambda name, path: seen.append((name, path.read_bytes())),
    )

    assert [name for name, _ in seen] == ["report.html", "report.pdf"]
    assert [(p.name, p.read_bytes()) for p in written] == seen  # the staged files moved whole
    html, pdf = seen[0][1], seen[1][1]
    assert pdf.startswith(b"%PDF")
    alone = render_report_html(two_estimates, options)
    assert len(_figures(html)) >= 5
    assert _figures(html) == _figures(alone)


def test_png_figures_are_opaque_rgb_at_print_resolution(two_estimates: EvaluationResult) -> None:
    """The PDF's figures are RGB PNGs (no alpha for the PDF engine to split) at 200 dpi."""
    plots = render_report_plots(two_estimates, ExportOptions(), formats=("png",))
    pngs = [p.png for p in plots.figures]
    if plots.clock is not None:
        pngs.append(plots.clock.png)
    assert pngs
    for png in pngs:
        assert png is not None
        image = Image.open(io.BytesIO(png))
        assert image.format == "PNG"
        assert image.mode == "RGB"
        assert image.width == int(WIDTH_IN * PNG_DPI)
        assert image.info["dpi"] == pytest.approx((PNG_DPI, PNG_DPI), abs=0.01)
        assert image.text["Software"] == "loceval"


@pytest.mark.parametrize(
    ("angles_deg", "expected_deg"),
    [
        ((30.0, 20.0, -10.0), (30.0, 20.0, -10.0)),
        ((-170.0, -45.0, 120.0), (-170.0, -45.0, 120.0)),
        ((10.0, 90.0, 20.0), (-10.0, 90.0, 0.0)),  # gimbal lock: only yaw - roll is defined
        ((10.0, -90.0, 20.0), (30.0, -90.0, 0.0)),  # and yaw + roll at -90 degrees
    ],
)
def test_yaw_pitch_roll_of_a_rotation_matrix(
    angles_deg: tuple[float, float, float], expected_deg: tuple[float, float, float]
) -> None:
    """The alignment table's angles are the z-y'-x'' turns that rebuild the matrix."""
    matrix = Rotation.from_euler("ZYX", np.array(angles_deg), degrees=True).as_matrix()
    got = yaw_pitch_roll_deg(matrix)
    assert got == pytest.approx(expected_deg, abs=1e-9)
    rebuilt = Rotation.from_euler("ZYX", np.array(got), degrees=True).as_matrix()
    np.testing.assert_allclose(rebuilt, matrix, atol=1e-12)
    assert all(math.isfinite(a) for a in got)


def test_each_figure_is_laid_out_once_and_drawn_once_per_format(
    two_estimates: EvaluationResult, monkeypatch: pytest.MonkeyPatch
) -> None:
    """One fixed layout per figure, shared by its SVG and PNG, no constrained layout, and no
    draw that renders nothing (savefig makes one to lay out a figure that has an engine)."""
    layouts: list[Figure] = []
    draws: list[Figure] = []
    constrained: list[Figure] = []
    lay_out, draw = figure_module.lay_out, Figure.draw
    execute = ConstrainedLayoutEngine.execute

    def counted_layout(fig: Figure) -> None:
        layouts.append(fig)
        lay_out(fig)

    def counted_draw(self: Figure, renderer: Any) -> None:
        draws.append(self)
        draw(self, renderer)

    def counted_constrained(self: ConstrainedLayoutEngine, fig: Figure) -> None:
        constrained.append(fig)
        execute(self, fig)

    monkeypatch.setattr(figure_module, "lay_out", counted_layout)
    monkeypatch.setattr(Figure, "draw", counted_draw)
    monkeypatch.setattr(ConstrainedLayoutEngine, "execute", counted_constrained)
    plots = render_report_plots(two_estimates, ExportOptions(), formats=("svg", "png"))

    drawn = [*plots.figures, *([plots.clock] if plots.clock is not None else [])]
    assert len(drawn) >= 5
    assert len(layouts) == len(drawn)
    assert len(set(map(id, layouts))) == len(layouts)
    assert constrained == []  # the constrained layout engine runs for none of them
    assert len(draws) == 2 * len(drawn)  # one SVG and one PNG each
    assert {id(fig): draws.count(fig) for fig in draws} == {id(fig): 2 for fig in layouts}
    for fig in layouts:
        assert fig.get_layout_engine() is None  # nothing left to lay the figure out again
    for plot in drawn:
        assert plot.svg is not None
        assert plot.png is not None
