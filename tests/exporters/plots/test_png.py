"""The report's PNG encoder: lossless, a PNG any reader opens, the resolution it was given."""

from __future__ import annotations

import io
import zlib

import numpy as np
import pytest
from PIL import Image

from exporters.plots.png import rgb_png


@pytest.mark.parametrize(("height", "width"), [(1, 1), (2, 3), (17, 1), (101, 257)])
def test_the_colours_read_back_exactly_and_alpha_is_dropped(height: int, width: int) -> None:
    """Pillow (an independent decoder) reads back every RGB byte; the image is RGB."""
    rng = np.random.default_rng(height * 1000 + width)
    rgba = rng.integers(0, 256, size=(height, width, 4), dtype=np.uint8)
    png = rgb_png(rgba, dpi=200, software="loceval")

    image = Image.open(io.BytesIO(png))
    assert image.format == "PNG"
    assert image.mode == "RGB"
    assert image.size == (width, height)
    np.testing.assert_array_equal(np.asarray(image), rgba[:, :, :3])
    assert image.info["dpi"] == pytest.approx((200, 200), abs=0.01)
    assert image.text["Software"] == "loceval"


def test_a_strided_canvas_is_read_as_its_pixels() -> None:
    """A view into a larger buffer (matplotlib's canvas reshaped) encodes what it shows."""
    big = np.arange(6 * 10 * 4, dtype=np.uint8).reshape(6, 10, 4)
    view = big[1:5, 2:9]
    image = Image.open(io.BytesIO(rgb_png(view, dpi=72, software="x")))
    np.testing.assert_array_equal(np.asarray(image), view[:, :, :3])


def test_every_chunk_carries_a_valid_crc() -> None:
    """Each chunk's CRC is the CRC-32 of its type and data (what strict readers check)."""
    png = rgb_png(np.full((3, 4, 4), 255, dtype=np.uint8), dpi=150, software="loceval")
    assert png.startswith(b"\x89PNG\r\n\x1a\n")
    at, kinds = 8, []
    while at < len(png):
        length = int.from_bytes(png[at : at + 4], "big")
        kind, data = png[at + 4 : at + 8], png[at + 8 : at + 8 + length]
        assert int.from_bytes(png[at + 8 + length : at + 12 + length], "big") == zlib.crc32(
            kind + data
        )
        kinds.append(kind)
        at += 12 + length
    assert kinds == [b"IHDR", b"pHYs", b"tEXt", b"IDAT", b"IEND"]


@pytest.mark.parametrize(
    "canvas",
    [
        np.zeros((2, 2, 3), dtype=np.uint8),  # no alpha channel
        np.zeros((2, 2, 4), dtype=np.float64),  # not bytes
        np.zeros((0, 2, 4), dtype=np.uint8),  # no pixel
        np.zeros((8, 4), dtype=np.uint8),  # flat
    ],
)
def test_a_canvas_of_another_shape_or_type_is_refused(canvas: np.ndarray) -> None:
    """Anything but (H, W, 4) uint8 with a pixel is a ValueError naming what it got."""
    with pytest.raises(ValueError, match=r"\(H, W, 4\) uint8"):
        rgb_png(canvas, dpi=200, software="loceval")
