"""The figures' PNG rows go into the PDF as they are; every other PNG as WeasyPrint makes it."""

from __future__ import annotations

import io
import shutil
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from exporters.plots.png import rgb_png
from exporters.report import html_to_pdf
from exporters.report.pdf_png import png_rows
from tests.exporters.report.test_report_pdf_images import _page, _pdf_images


def _idat(png: bytes) -> bytes:
    """The IDAT content of a PNG, read chunk by chunk here (independent of png_rows)."""
    at, rows = 8, b""
    while at < len(png):
        (length,) = struct.unpack(">I", png[at : at + 4])
        if png[at + 4 : at + 8] == b"IDAT":
            rows += png[at + 8 : at + 8 + length]
        at += 12 + length
    return rows


def _pillow_png(image: np.ndarray | Image.Image, **options: object) -> bytes:
    """A PNG written by Pillow (an independent encoder)."""
    out = io.BytesIO()
    picture = image if isinstance(image, Image.Image) else Image.fromarray(image)
    picture.save(out, format="PNG", **options)
    return out.getvalue()


def _interlaced(png: bytes) -> bytes:
    """The PNG with its IHDR marked Adam7-interlaced (Pillow writes no interlaced PNG)."""
    header = png[12:28] + b"\x01"  # type, width, height, depth, colour, method, filter
    return png[:12] + header + struct.pack(">I", zlib.crc32(header)) + png[33:]


RNG = np.random.default_rng(11)
RGB = RNG.integers(0, 256, size=(24, 40, 3), dtype=np.uint8)


def test_the_rows_of_an_rgb_png_are_its_idat() -> None:
    """An 8-bit RGB PNG (the report's figures, or Pillow's) gives its IDAT content, whole."""
    ours = rgb_png(np.dstack([RGB, np.full(RGB.shape[:2], 255, np.uint8)]), dpi=96, software="t")
    assert png_rows(ours, "RGB") == _idat(ours)
    pillows = _pillow_png(RGB)
    assert png_rows(pillows, "RGB") == _idat(pillows)
    grey = _pillow_png(RGB[:, :, 0])
    assert png_rows(grey, "L") == _idat(grey)
    # the rows decompress to one filter byte and the samples of each row
    assert len(zlib.decompress(png_rows(ours, "RGB") or b"")) == 24 * (1 + 3 * 40)


@pytest.mark.parametrize(
    ("png", "mode"),
    [
        (_pillow_png(RGB), "L"),  # declared otherwise than the file holds
        (_pillow_png(np.dstack([RGB, RGB[:, :, :1]])), "RGBA"),  # alpha: WeasyPrint splits it
        (_pillow_png(RGB[:, :, 0].astype(np.uint16) * 257), "L"),  # 16 bits per sample
        (_pillow_png(RGB[:, :, 0] >= 128), "L"),  # 1 bit per sample
        (_interlaced(_pillow_png(RGB)), "RGB"),  # Adam7: rows a PDF cannot take
        (_pillow_png(Image.fromarray(RGB).convert("P")), "RGB"),  # a palette
        (_pillow_png(RGB)[:-30], "RGB"),  # cut short
        (b"GIF89a" + bytes(40), "RGB"),
        (b"", "RGB"),
    ],
)
def test_other_pngs_are_left_to_weasyprint(png: bytes, mode: str) -> None:
    """Anything but whole 8-bit grey or RGB rows without interlacing gives None."""
    assert png_rows(png, mode) is None


@pytest.mark.pdf
def test_the_pdf_holds_the_figures_rows_as_written() -> None:
    """The report's PNG rows are in the PDF byte for byte (no second compression)."""
    canvas = np.dstack([RGB, np.full(RGB.shape[:2], 255, np.uint8)])
    png = rgb_png(canvas, dpi=96, software="t")
    assert _idat(png) in html_to_pdf(_page([png], "one figure"))


@pytest.mark.pdf
@pytest.mark.skipif(shutil.which("pdfimages") is None, reason="needs poppler-utils (pdfimages)")
def test_pngs_weasyprint_encodes_itself_keep_their_pixels(tmp_path: Path) -> None:
    """Grey, palette and RGBA PNGs reach the PDF with their pixels (read back by poppler)."""
    grey = RGB[:, :, 0]
    palette = Image.fromarray(RGB).convert("P")
    opaque = np.dstack([RGB, np.full(grey.shape, 255, np.uint8)])
    pngs = [_pillow_png(grey), _pillow_png(palette), _pillow_png(opaque)]
    found = _pdf_images(html_to_pdf(_page(pngs, "three kinds")), tmp_path)
    colour = [f for f in found if f.shape == RGB.shape]
    np.testing.assert_array_equal(colour[0], np.dstack([grey] * 3))
    np.testing.assert_array_equal(colour[1], np.asarray(palette.convert("RGB")))
    np.testing.assert_array_equal(colour[2], RGB)
