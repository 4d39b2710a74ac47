"""An opaque RGB PNG from a rendered RGBA canvas, encoded with NumPy and zlib.

Pillow's PNG encoder tries five row filters on every row and keeps the best; on a report
figure (1400 x 1000 pixels, mostly white) that took 0.11 s at its fastest zlib level. Here
every row gets the PNG "Up" filter (its difference from the row above, one vectorised
subtraction for the whole image) and zlib's default level: the compressed rows go into the
PDF as they are (:mod:`exporters.report.pdf_png`), so they are compressed once, about as
small as Pillow made them, in 15 ms per figure (level 1 took 7 ms for a file a fifth
larger; measured on the fr2_desk report's figures).

The file is a plain PNG (ISO/IEC 15948): IHDR (8-bit RGB, no interlace), pHYs (the
resolution), tEXt (the software), one IDAT and IEND.
"""

from __future__ import annotations

import struct
import zlib
from typing import Final

import numpy as np

__all__ = ["rgb_png"]

_SIGNATURE: Final = b"\x89PNG\r\n\x1a\n"
_FILTER_UP: Final = 2
"""PNG filter type 2: each byte minus the byte above it (the first row has zeros above)."""
_ZLIB_LEVEL: Final = 6
_METRES_PER_INCH: Final = 0.0254


def _chunk(kind: bytes, data: bytes) -> bytes:
    """Return one PNG chunk: length, type, data and the CRC of type and data."""
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def rgb_png(rgba: np.ndarray, *, dpi: float, software: str) -> bytes:
    """Encode the colour of an (H, W, 4) uint8 RGBA canvas as an RGB PNG.

    The alpha channel is dropped: the report's figures have an opaque background, and a
    PDF engine would otherwise split it into a soft mask.

    Args:
        rgba: the canvas, rows top to bottom.
        dpi: the resolution written in the pHYs chunk, dots per inch.
        software: the tEXt ``Software`` entry.

    Raises:
        ValueError: ``rgba`` is not an (H, W, 4) uint8 array with at least one pixel.
    """
    if rgba.dtype != np.uint8 or rgba.ndim != 3 or rgba.shape[2] != 4 or 0 in rgba.shape:
        msg = f"Expected an (H, W, 4) uint8 canvas, got {rgba.dtype} of shape {rgba.shape}."
        raise ValueError(msg)
    height, width = int(rgba.shape[0]), int(rgba.shape[1])
    # The differences are taken over whole RGBA pixels (contiguous memory, a third of the
    # time of subtracting the strided RGB bytes) and their colour copied into the rows.
    up = np.empty_like(rgba)
    up[0] = rgba[0]
    np.subtract(rgba[1:], rgba[:-1], out=up[1:])  # uint8 wraps modulo 256, as PNG's Up
    rows = np.empty((height, 1 + 3 * width), dtype=np.uint8)
    rows[:, 0] = _FILTER_UP
    pixels = rows[:, 1:].view()
    pixels.shape = (height, width, 3)  # a view of the rows' bytes (raises rather than copy)
    pixels[...] = up[:, :, :3]
    per_metre = round(dpi / _METRES_PER_INCH)
    return b"".join(
        (
            _SIGNATURE,
            _chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)),
            _chunk(b"pHYs", struct.pack(">IIB", per_metre, per_metre, 1)),
            _chunk(b"tEXt", b"Software\x00" + software.encode("latin-1")),
            _chunk(b"IDAT", zlib.compress(rows.data, _ZLIB_LEVEL)),
            _chunk(b"IEND", b""),
        )
    )
