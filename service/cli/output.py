"""What the command line prints: text with its control characters made visible.

Tables, inspections and messages hold names and paths from the inputs (a topic named with
a terminal escape, a file name with a bidirectional override); :func:`emit` is the one
place that prints them, through :func:`loceval.core.display.display_text`.
"""

from __future__ import annotations

import sys
from typing import TextIO

from loceval.core.display import display_text
from loceval.core.quantities import ASCII_SPELLINGS

__all__ = ["emit", "shown_as"]


def emit(text: str, *, file: TextIO | None = None) -> None:
    """Print ``text`` (one or more lines) without control characters (tabs and LF kept).

    The symbols (±, ≤, →) are written as ASCII (+/-, <=, ->) on a terminal whose encoding
    lacks them (:data:`loceval.core.quantities.ASCII_SPELLINGS`); anything else it cannot
    show (U+FFFD on a Latin-1 terminal) becomes ``?``.
    """
    stream = file or sys.stdout
    print(shown_as(text, getattr(stream, "encoding", None) or "utf-8"), file=stream)


def shown_as(text: str, encoding: str) -> str:
    """Return ``text`` as :func:`emit` prints it on a stream of ``encoding``."""
    shown = display_text(text, one_line=False)
    for symbol, ascii_spelling in ASCII_SPELLINGS.items():
        try:
            symbol.encode(encoding)
        except UnicodeEncodeError:
            shown = shown.replace(symbol, ascii_spelling)
    return shown.encode(encoding, errors="replace").decode(encoding)
