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
from PIL import Image

from exporters import write_artifacts
from exporters.options import ExportOptions
from exporters.plots import figure as figure_module
from exporters.plots.figure import PNG_DPI, WIDTH_IN
from exporters.plots.svg.canvas import Figure as KitFigure
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
    """One fixed layout per figure and one drawing, its SVG; the PNG is that SVG rasterised.

    The report's figures are the figure kit's (no matplotlib figure, no constrained layout);
    a figure asked for in both formats is laid out and drawn once.
    """
    layouts: list[KitFigure] = []
    drawings: list[KitFigure] = []
    rasterised: list[bytes] = []
    lay_out, svg, png_of_svg = KitFigure.lay_out, KitFigure.svg, figure_module.png_of_svg

    def counted_layout(fig: KitFigure) -> None:
        layouts.append(fig)
        lay_out(fig)

    def counted_svg(fig: KitFigure) -> bytes:
        drawings.append(fig)
        return svg(fig)

    def counted_png(document: bytes, **kwargs: Any) -> bytes:
        rasterised.append(document)
        return png_of_svg(document, **kwargs)

    monkeypatch.setattr(KitFigure, "lay_out", counted_layout)
    monkeypatch.setattr(KitFigure, "svg", counted_svg)
    monkeypatch.setattr(figure_module, "png_of_svg", counted_png)
    plots = render_report_plots(two_estimates, ExportOptions(), formats=("svg", "png"))

    drawn = [*plots.figures, *([plots.clock] if plots.clock is not None else [])]
    assert len(drawn) >= 5
    assert len(layouts) == len(drawn)
    assert len(set(map(id, layouts))) == len(layouts)
    assert [id(fig) for fig in drawings] == [id(fig) for fig in layouts]  # one drawing each
    assert rasterised == [plot.svg for plot in drawn]  # the PNG shows the SVG's drawing
    for plot in drawn:
        assert plot.svg is not None
        assert plot.png is not None
