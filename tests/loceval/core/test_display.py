"""Names and messages shown as text: :func:`loceval.core.display.display_text` and Jinja's
finalize."""

from __future__ import annotations

import pytest
from markupsafe import Markup

from loceval.core.display import REPLACEMENT, display_text, shown_text


@pytest.mark.parametrize(
    ("raw", "shown"),
    [
        ("RTAB-Map", "RTAB-Map"),
        ("red\x1b[31m", f"red{REPLACEMENT}[31m"),
        ("nul\x00byte", f"nul{REPLACEMENT}byte"),
        ("csi\x9b2J del\x7f", f"csi{REPLACEMENT}2J del{REPLACEMENT}"),
        ("abc\u202efdp.exe", f"abc{REPLACEMENT}fdp.exe"),
        ("iso\u2066late\u2069 mark\u200f", f"iso{REPLACEMENT}late{REPLACEMENT} mark{REPLACEMENT}"),
        ("argv\udc9bbyte", f"argv{REPLACEMENT}byte"),
        ("  two\r\nlines\tand  tabs ", "two lines and tabs"),
        ("<script>alert(1)</script>", "<script>alert(1)</script>"),  # HTML is escaped later
        ("Zürich 東京 🙂", "Zürich 東京 🙂"),
    ],
)
def test_one_line_names(raw: str, shown: str) -> None:
    """Controls, bidi controls and lone surrogates become U+FFFD; layout becomes one space."""
    assert display_text(raw) == shown


def test_multi_line_text_keeps_its_lines() -> None:
    """Messages and tables keep LF and tabs; CR LF and other line ends become LF."""
    text = "row 1\tA\r\nrow 2\x1b[0m\rrow 3\u2028end"
    assert display_text(text, one_line=False) == f"row 1\tA\nrow 2{REPLACEMENT}[0m\nrow 3\nend"


def test_shown_text_cleans_strings_and_keeps_markup() -> None:
    """Jinja's finalize hook cleans every printed string but leaves Markup and numbers alone."""
    assert shown_text("a\x1bb") == f"a{REPLACEMENT}b"
    markup = Markup("<b>\x1b</b>")
    assert shown_text(markup) is markup
    assert shown_text(3.5) == 3.5
