"""What the command line prints: text with its control characters made visible.

Tables, inspections and messages hold names and paths from the inputs (a topic named with
a terminal escape, a file name with a bidirectional override); :func:`emit` is the one
place that prints them, through :func:`loceval.display.display_text`.
"""

from __future__ import annotations

import sys
from typing import TextIO

from loceval.display import display_text

__all__ = ["emit"]


def emit(text: str, *, file: TextIO | None = None) -> None:
    """Print ``text`` (one or more lines) without control characters (tabs and LF kept)."""
    print(display_text(text, one_line=False), file=file or sys.stdout)
