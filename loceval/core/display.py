"""Text from the outside shown as text: names, titles and messages without control characters.

Names (trajectory, topic, rigid body, dataset, control point), titles and messages come from
files and requests, so they may hold terminal escapes (``ESC [31m``), NUL, C1 controls or
Unicode bidirectional overrides that make a name read backwards. :func:`display_text` is the
one function that makes such text safe to show: every front door and exporter that shows a
name gets it from here (HTML is escaped on top by the templates' autoescape).
"""

from __future__ import annotations

import re
from typing import Final

__all__ = ["REPLACEMENT", "display_text", "shown_text"]

REPLACEMENT: Final = "\ufffd"
"""What an unsafe character becomes: the Unicode replacement character, visible everywhere."""

_SPACES: Final = re.compile(r"[\t\n\r\v\f\u2028\u2029]")
"""Layout characters: a space in one-line text; tabs and line ends stay in multi-line text."""

_LINE_ENDS: Final = re.compile(r"\r\n|[\r\v\f\u2028\u2029]")
"""Line ends of every kind, made LF in multi-line text."""

_UNSAFE: Final = re.compile(
    "[\x00-\x08\x0b\x0c\x0e-\x1f\x7f-\x9f\u061c\u200e\u200f\u202a-\u202e\u2066-\u2069\ud800-\udfff]"
)
"""C0 and C1 controls (ESC, NUL, DEL, CSI ...), the bidirectional marks, embeddings,
overrides and isolates (U+061C, U+200E/F, U+202A-E, U+2066-9), and lone surrogates (bytes
of a command line or file name that were not UTF-8), which no encoder can write."""


def display_text(text: str, *, one_line: bool = True) -> str:
    """Return ``text`` safe to show in a terminal, a report, a CAD file or a log.

    Control characters and bidirectional controls become U+FFFD (visible, so a name that
    held one still looks odd instead of silently changing). One-line text (names, titles)
    also turns tabs and line ends into spaces, collapses runs of whitespace and strips the
    ends; multi-line text (messages, tables) keeps its tabs and line ends.

    Args:
        text: the text as received.
        one_line: make it one line (names and titles).

    Returns:
        The text with every unsafe character replaced.
    """
    if one_line:
        text = _SPACES.sub(" ", text)
        text = _UNSAFE.sub(REPLACEMENT, text)
        return " ".join(text.split())
    return _UNSAFE.sub(REPLACEMENT, _LINE_ENDS.sub("\n", text))


def shown_text(value: object) -> object:
    """Jinja's ``finalize``: every text a template prints loses its control characters.

    Autoescape makes names inert HTML; this makes them plain text too (no terminal escapes,
    NUL or bidirectional overrides reach a page). Markup (``__html__``) stays as it is.
    """
    if isinstance(value, str) and not hasattr(value, "__html__"):
        return display_text(value, one_line=False)
    return value
