"""What the command line prints: text with its control characters made visible.

Tables, inspections and messages hold names and paths from the inputs (a topic named with
a terminal escape, a file name with a bidirectional override); :func:`emit` is the one
place that prints them, through :func:`loceval.core.display.display_text`.
"""

from __future__ import annotations

import sys
from typing import TextIO

from loceval.core.display import display_text

__all__ = ["emit"]


def emit(text: str, *, file: TextIO | None = None) -> None:
    """Print ``text`` (one or more lines) without control characters (tabs and LF kept).

    What the terminal's encoding cannot show (U+FFFD on a Latin-1 terminal) becomes ``?``.
    """
    stream = file or sys.stdout
    shown = display_text(text, one_line=False)
    encoding = getattr(stream, "encoding", None) or "utf-8"
    print(shown.encode(encoding, errors="replace").decode(encoding), file=stream)
