"""Text widths of DejaVu Sans, the figures' font, without reading the font at run time.

The figures' layout needs how wide each text is (a y axis' tick labels decide the left
margin). The advance widths of DejaVu Sans and DejaVu Sans Bold (the fonts the PDF embeds
from matplotlib's font folder, :mod:`exporters.report.typeset`, and the first the SVG names)
are tabled in :mod:`exporters.plots.svg._glyph_widths` for the characters a figure writes;
a character outside the table counts as wide as an ``M`` (a margin a little too wide, never
a label cut). Kerning is not applied: DejaVu's kerning narrows a label by a few per cent at
most, so the margins err on the generous side.

The table is generated from the font files by :mod:`exporters.plots.svg.widths_table`
(``python -m exporters.plots.svg.widths_table``); ``tests/exporters/plots/test_svg_kit.py``
checks it against the fonts.
"""

from __future__ import annotations

import functools
import importlib.util
from pathlib import Path
from typing import TYPE_CHECKING, Final

from exporters.plots.svg._glyph_widths import BOLD, REGULAR, UNITS_PER_EM

if TYPE_CHECKING:
    import typst

__all__ = ["fit_text", "font_folder", "text_width_pt", "typst_fonts"]

_FALLBACK: Final = "M"


def text_width_pt(text: str, size_pt: float, *, bold: bool = False) -> float:
    """Return how wide ``text`` is set in DejaVu Sans (Bold) at ``size_pt``, points."""
    table = BOLD if bold else REGULAR
    fallback = table[_FALLBACK]
    units = sum(table.get(c, fallback) for c in text)
    return units * size_pt / UNITS_PER_EM


def fit_text(text: str, size_pt: float, width_pt: float) -> str:
    """Return ``text``, cut with an ellipsis if it is wider than ``width_pt`` (a long name)."""
    if text_width_pt(text, size_pt) <= width_pt:
        return text
    table = REGULAR
    fallback = table[_FALLBACK]
    room = width_pt * UNITS_PER_EM / size_pt - table.get("…", fallback)
    widths = [table.get(c, fallback) for c in text]  # one name's characters
    cut = 0
    used = 0
    while cut < len(widths) and used + widths[cut] <= room:
        used += widths[cut]
        cut += 1
    return text[:cut].rstrip() + "…"


def font_folder() -> Path:
    """Matplotlib's folder of DejaVu fonts, found without importing matplotlib."""
    spec = importlib.util.find_spec("matplotlib")
    if spec is None or spec.origin is None:
        msg = "matplotlib is not installed: its DejaVu fonts are the figures' fonts."
        raise ModuleNotFoundError(msg)
    return Path(spec.origin).parent / "mpl-data" / "fonts" / "ttf"


@functools.cache
def typst_fonts() -> typst.Fonts:
    """DejaVu Sans (and Mono) from matplotlib's font folder, read by Typst once per process.

    The fonts of the PDFs and of the figures' PNGs. The folder is found without importing
    matplotlib (a third of a second). The system's fonts are not searched (a machine without
    fonts typesets the same PDF); Typst's own embedded fonts stay available as a fallback
    for rare symbols.
    """
    import typst  # noqa: PLC0415  (loceval[report]; imported with the first PDF or PNG)

    return typst.Fonts(
        include_system_fonts=False, include_embedded_fonts=True, font_paths=[str(font_folder())]
    )
