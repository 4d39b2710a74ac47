"""The text of a report as printed: the HTML's text blocks and the PDF's text (pdftotext).

The PDF is typeset by Typst from its own template and the HTML by Jinja2 from another, both
from one view model. :func:`text_differences` holds them to the same words: every text block
the HTML prints (a paragraph, a table cell, a caption, a heading, a list item) is found
whole in the PDF's text, and the PDF has no text that is not one of those blocks. It knows
nothing of any one report: a section, sentence or number one template shows and the other
does not is a difference.

The figures are the same SVG documents in both (an ``<img>`` in the HTML, an image in the
PDF); their texts (tick labels, axis labels, legends, notes) are set as text, so the PDF's
text has them too: each ``<text>`` of an embedded SVG figure counts as a block of the HTML.
"""

from __future__ import annotations

import base64
import html as html_module
import re
import subprocess
from html.parser import HTMLParser
from pathlib import Path

from tests.conftest import require_tool

BLOCKS = frozenset(
    {"p", "li", "td", "th", "caption", "h1", "h2", "h3", "h4", "figcaption", "dt", "dd", "footer"}
)
"""The HTML elements whose text is one block of the printed page."""
_SKIPPED = frozenset({"head", "script", "style", "svg", "template"})
_VOID = frozenset({"br", "wbr", "img", "col", "meta", "link", "input", "hr", "source"})
_HIDDEN_CLASSES = frozenset({"placeholder"})
"""Classes the print stylesheet hides (``.best-mark.placeholder``: visibility hidden)."""
_SPACED_CLASSES = frozenset({"badge"})
"""Inline boxes the stylesheet sets apart with a margin: a word of their own on the page."""
_CONTENTS_LEADER = re.compile(r"(?: ?\.){3,} ?\d+(?= |$)")
"""The dot leader and page number of an entry of the PDF's contents list."""
_LIST_MARKER = re.compile(r"(?<!\S)•(?!\S)")
_SVG_FIGURE = "data:image/svg+xml;base64,"
_SVG_TEXT = re.compile(r"<text\b[^>]*>(.*?)</text>", re.DOTALL)
"""A list item's bullet: drawn by the stylesheet in the HTML, a glyph in the PDF."""


def normalise(text: str) -> str:
    """Collapse whitespace (no-break spaces included) and fold case (CSS ``uppercase``)."""
    return " ".join(text.replace("\u00a0", " ").replace("\u200b", "").split()).casefold()


class _Blocks(HTMLParser):
    """Collects the text of every block element, innermost first, skipping hidden parts."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.blocks: list[str] = []
        self._stack: list[tuple[str, bool, list[str] | None, bool]] = []
        # (tag, hidden, its own text buffer if a block, spaced after)

    def _hidden(self) -> bool:
        return any(hidden for _, hidden, _, _ in self._stack)

    def _buffer(self) -> list[str] | None:
        return next((b for _, _, b, _ in reversed(self._stack) if b is not None), None)

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        classes = set((dict(attrs).get("class") or "").split())
        if tag in _VOID:
            if tag == "br" and (buffer := self._buffer()) is not None:
                buffer.append(" ")
            src = dict(attrs).get("src") or ""
            if tag == "img" and src.startswith(_SVG_FIGURE) and not self._hidden():
                svg = base64.b64decode(src.removeprefix(_SVG_FIGURE)).decode()
                texts = (normalise(html_module.unescape(t)) for t in _SVG_TEXT.findall(svg))
                self.blocks.extend(t for t in texts if t)
            return
        hidden = tag in _SKIPPED or bool(classes & _HIDDEN_CLASSES)
        spaced = bool(classes & _SPACED_CLASSES)
        self._stack.append((tag, hidden, [] if tag in BLOCKS else None, spaced))

    def handle_endtag(self, tag: str) -> None:
        if tag in _VOID:
            return
        while self._stack:
            open_tag, _, buffer, spaced = self._stack.pop()
            if buffer is not None and (text := normalise("".join(buffer))):
                self.blocks.append(text)
            if spaced and (outer := self._buffer()) is not None:
                outer.append(" ")
            if open_tag == tag:
                break

    def handle_data(self, data: str) -> None:
        if self._hidden():
            return
        buffer = self._buffer()
        if buffer is not None:
            buffer.append(data)
        elif data.strip():
            self.blocks.append(normalise(data))


def printed_blocks(html: str) -> list[str]:
    """Return the normalised text blocks of a report's HTML, in document order by end."""
    parser = _Blocks()
    parser.feed(html)
    parser.close()
    return parser.blocks


def pdf_pages(pdf: bytes, tmp_path: Path) -> list[list[str]]:
    """Return each page's lines as ``pdftotext -raw`` reads them (content stream order)."""
    tool = require_tool("pdftotext")
    path = tmp_path / "printed.pdf"
    path.write_bytes(pdf)
    text = subprocess.run(
        [tool, "-raw", "-enc", "UTF-8", str(path), "-"], capture_output=True, text=True, check=True
    ).stdout
    pages = text.split("\f")
    if pages and not pages[-1].strip():
        pages.pop()
    return [[line for line in page.splitlines() if line.strip()] for page in pages]


def pdf_body(pdf: bytes, tmp_path: Path, *, title: str) -> str:
    """Return the PDF's text without its running heads and feet, normalised.

    Every page starts with the running head (the title, then the section) and ends with
    ``page N of M``; both are checked and left out. A line broken after a path separator
    (``/``) continues the name without a space, as it does on the page.
    """
    pages = pdf_pages(pdf, tmp_path)
    lines: list[str] = []
    for n, page in enumerate(pages, start=1):
        head, *body, foot = page
        assert normalise(head).startswith(normalise(title)), (n, head)
        assert foot.strip() == f"page {n} of {len(pages)}", (n, foot)
        lines.extend(body)
    text = ""
    for raw in lines:
        line = raw.replace("\u200b", "")
        text += line if text.endswith(("/", "\\")) or not text else " " + line
    return normalise(text)


def text_differences(html: str, pdf: bytes, tmp_path: Path, *, title: str) -> tuple[list, list]:
    """Return (HTML blocks missing from the PDF, PDF text that is no HTML block).

    Forward: each printed block of the HTML must occur in the PDF's text, whole (words
    in the same order, as a site engineer reads them). Reverse: every occurrence of every
    block is taken out of the PDF's text, longest first and only at word boundaries;
    the contents list's dot leaders and page numbers go too; whatever is left is text the
    PDF shows and the HTML does not.
    """
    blocks = printed_blocks(html)
    body = pdf_body(pdf, tmp_path, title=title)
    missing = [block for block in dict.fromkeys(blocks) if block not in body]
    rest = _LIST_MARKER.sub(" ", _CONTENTS_LEADER.sub(" ", body))
    for block in sorted(set(blocks), key=len, reverse=True):
        rest = re.sub(rf"(?<!\S){re.escape(block)}(?!\S)", " ", rest)
    extra = rest.split()
    return missing, extra
