"""PNG figures into the PDF as they are: their compressed rows, not WeasyPrint's re-encoding.

A PDF holds a PNG's pixels as a FlateDecode image stream with the PNG predictors, which is
exactly the content of the PNG's IDAT chunks (ISO 32000-1, 7.4.4.4: ``/Predictor 15`` with
``/Colors``, ``/BitsPerComponent`` and ``/Columns`` of the image). WeasyPrint 70 instead
decodes every PNG with Pillow and encodes it again (``RasterImage._get_png_data``): 35 ms
per report figure, a quarter of second per report, for bytes that say the same.

:func:`install` replaces that one step, process-wide, by one that hands over the IDAT
chunks of the PNG Pillow was opened on when its rows can go to the PDF unchanged (8 bits
per sample, grey or RGB, no interlacing, the mode WeasyPrint declares for it), and
otherwise calls WeasyPrint's own. Any PNG qualifies, not only the report's: the stream is
the one a PDF reader decodes to the same pixels
(``tests/exporters/report/test_report_pdf_images.py`` reads them back with poppler).
"""

from __future__ import annotations

import io
import struct
from collections.abc import Callable
from types import ModuleType
from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    from PIL import Image

__all__ = ["install", "png_rows"]

_SIGNATURE: Final = b"\x89PNG\r\n\x1a\n"
_COLOUR_TYPES: Final = {"L": 0, "RGB": 2}
"""The Pillow modes whose PNG rows go to the PDF as they are, and their PNG colour type."""
_MARK: Final = "_loceval_png_rows"


def png_rows(data: bytes, mode: str) -> bytes | None:
    """Return the IDAT content of a PNG whose rows a PDF can take as they are, else None.

    Args:
        data: the PNG file.
        mode: the Pillow mode the image is declared with in the PDF (``RGB`` or ``L``).

    Returns:
        The concatenated IDAT chunk data (a zlib stream of filtered rows); None when the
        file is not a PNG of 8-bit ``mode`` samples without interlacing, or is cut short.
    """
    colour_type = _COLOUR_TYPES.get(mode)
    if colour_type is None or not data.startswith(_SIGNATURE) or len(data) < 33:
        return None
    length, kind = struct.unpack_from(">I4s", data, 8)
    if kind != b"IHDR" or length != 13:
        return None
    depth, colour, _compression, _filters, interlace = struct.unpack_from(">BBBBB", data, 24)
    if depth != 8 or colour != colour_type or interlace != 0:
        return None
    rows = []
    at = 8
    while at + 8 <= len(data):
        length, kind = struct.unpack_from(">I4s", data, at)
        end = at + 8 + length
        if end + 4 > len(data):
            return None  # cut short: let Pillow say what it makes of it
        if kind == b"IDAT":
            rows.append(data[at + 8 : end])
        elif kind == b"IEND":
            return b"".join(rows) if rows else None
        at = end + 4  # past the CRC
    return None


def install(images: ModuleType) -> None:
    """Make WeasyPrint's ``images`` module pass PNG rows through (once per process).

    A WeasyPrint without the step (another version) is left as it is: its PDFs stay right,
    only slower.
    """
    raster = getattr(images, "RasterImage", None)
    original: Callable[[Image.Image], bytes] | None = getattr(raster, "_get_png_data", None)
    if raster is None or original is None or getattr(original, _MARK, False):
        return

    def get_png_data(pillow_image: Image.Image) -> bytes:
        source = getattr(pillow_image, "fp", None)
        if pillow_image.format == "PNG" and isinstance(source, io.BytesIO):
            rows = png_rows(source.getvalue(), pillow_image.mode)
            if rows is not None:
                return rows
        return original(pillow_image)

    setattr(get_png_data, _MARK, True)
    raster._get_png_data = staticmethod(get_png_data)  # noqa: SLF001
