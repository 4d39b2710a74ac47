"""Writes :mod:`exporters.plots.svg._glyph_widths` from the DejaVu fonts (a developer's tool).

``python -m exporters.plots.svg.widths_table`` reads the advance widths of
:data:`CHARACTERS` from matplotlib's DejaVu Sans and DejaVu Sans Bold with fontTools (a
dependency of matplotlib) and writes the table :mod:`exporters.plots.svg.metrics` reads.
Run it after a matplotlib upgrade changes the fonts; ``tests/exporters/plots/test_svg_kit.py``
fails until then.
"""

from __future__ import annotations

from pathlib import Path
from typing import Final

from exporters.plots.svg.metrics import font_folder

__all__ = ["CHARACTERS", "generated_table"]

CHARACTERS: Final = (
    "".join(chr(c) for c in range(0x20, 0x7F))
    + "".join(chr(c) for c in range(0xA0, 0x180))
    + "".join(chr(c) for c in range(0x391, 0x3CA))
    + "–—‘’“”…·•→←↑↓↔≤≥±×÷°µ−≈≠∞√∆✓✗"
)
"""The characters tabled: Latin-1 and Latin Extended-A, Greek, and the report's symbols."""


def _font_widths(path: Path) -> tuple[int, dict[str, int]]:
    """Read the advance widths of :data:`CHARACTERS` from a TrueType file (fontTools)."""
    from fontTools.ttLib import TTFont  # type: ignore[import-untyped]  # noqa: PLC0415

    font = TTFont(path)
    cmap = font.getBestCmap()
    metrics = font["hmtx"].metrics
    widths = {c: int(metrics[cmap[ord(c)]][0]) for c in CHARACTERS if ord(c) in cmap}
    return int(font["head"].unitsPerEm), widths


def _quoted(text: str) -> str:
    """A string literal in double quotes, as the formatter writes it."""
    escaped = {"\\": "\\\\", '"': '\\"'}
    body = "".join(
        escaped.get(c, c) if c.isprintable() and c not in "\xa0\xad" else f"\\x{ord(c):02x}"
        for c in text
    )
    return f'"{body}"'


def generated_table() -> str:
    """Return the source of :mod:`exporters.plots.svg._glyph_widths`, read from the fonts."""
    units, regular = _font_widths(font_folder() / "DejaVuSans.ttf")
    _, bold = _font_widths(font_folder() / "DejaVuSans-Bold.ttf")
    lines = [
        '"""Advance widths of DejaVu Sans and DejaVu Sans Bold, font units (generated).',
        "",
        "Written by ``python -m exporters.plots.svg.widths_table`` from matplotlib's copies of",
        "the fonts (DejaVu fonts licence, see matplotlib's LICENSE_DEJAVU). Do not edit.",
        '"""',
        "",
        "from typing import Final",
        "",
        f"UNITS_PER_EM: Final = {units}",
    ]
    bold = {c: bold.get(c, regular[c]) for c in regular}  # one character list for both
    chars = "".join(regular)
    lines.append("_CHARACTERS: Final = (")
    lines.extend(f"    {_quoted(chars[i : i + 40])}" for i in range(0, len(chars), 40))
    lines.append(")")
    for name, table in (("REGULAR", regular), ("BOLD", bold)):
        numbers = [str(w) for w in table.values()]
        lines.append(f'_{name}_WIDTHS: Final = """')
        lines.extend(" ".join(numbers[i : i + 16]) for i in range(0, len(numbers), 16))
        lines.append('"""')
        lines.append(
            f"{name}: Final = dict(zip(_CHARACTERS, map(int, _{name}_WIDTHS.split()), strict=True))"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    Path(__file__).with_name("_glyph_widths.py").write_text(generated_table(), encoding="utf-8")
