"""Read the tables of a rendered HTML report back as text, as a reader sees them."""

from __future__ import annotations

from html.parser import HTMLParser
from typing import Literal

__all__ = ["html_tables"]


class _Tables(HTMLParser):
    """Collect every table's visible cell texts (aria-hidden text skipped), by table name.

    A table's name is its caption (``key="caption"``; ``table<n>`` for one without, n
    counting from 0) or its ``class`` attribute (``key="class"``; empty without one).
    """

    def __init__(self, key: Literal["caption", "class"]) -> None:
        super().__init__()
        self.tables: dict[str, list[list[str]]] = {}
        self._key = key
        self._caption: list[str] | None = None
        self._rows: list[list[str]] = []
        self._cell: list[str] | None = None
        self._name = ""
        self._hidden = 0

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        if self._hidden or ("aria-hidden", "true") in attrs:
            self._hidden += 1
        if tag == "table":
            self._rows = []
            if self._key == "class":
                self._name = dict(attrs).get("class") or ""
            else:
                self._name = f"table{len(self.tables)}"
        elif tag == "caption" and self._key == "caption":
            self._caption = []
        elif tag == "tr":
            self._rows.append([])
        elif tag in {"td", "th"}:
            self._cell = []

    def handle_endtag(self, tag: str) -> None:
        if self._hidden:
            self._hidden -= 1
            return
        if tag == "caption" and self._caption is not None:
            self._name = " ".join("".join(self._caption).split())
            self._caption = None
        elif tag in {"td", "th"} and self._cell is not None:
            self._rows[-1].append(" ".join("".join(self._cell).split()))
            self._cell = None
        elif tag == "table":
            self.tables[self._name] = self._rows

    def handle_data(self, data: str) -> None:
        if self._hidden:
            return
        if self._caption is not None:
            self._caption.append(data)
        if self._cell is not None:
            self._cell.append(data)


def html_tables(
    html: str, *, key: Literal["caption", "class"] = "caption"
) -> dict[str, list[list[str]]]:
    """Return each table's rows of cell texts (white space folded), by caption or class."""
    parser = _Tables(key)
    parser.feed(html)
    return parser.tables
