"""JSON documents with finite numbers only: the one writer of result documents.

JSON has no NaN or infinity. A document that holds one (an input large enough to overflow
a computation) is refused with a message naming where, never written as invalid JSON.

Large documents (tens of thousands of curves) are laid out to a depth (``levels``): the
outer containers indented, everything deeper one compact line each. Python's JSON encoder
is written in C only without indentation, so a document indented all the way down is
encoded item by item in Python, seven times slower. Items a writer has already encoded
(:class:`JSONItems`: the curves of tens of thousands of ATE runs, each its own line) are
placed as they are.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Mapping

from exporters.errors import ExportError

__all__ = ["JSONItems", "finite_json"]


class JSONItems(list[str]):
    """A list whose items are JSON text already, each a container in one compact line.

    What :func:`json.dumps` writes for each item, made by a writer of tens of thousands of
    them at once; :func:`finite_json` lays the list out as it would lay out the list of
    those containers, placing each item as it is. The writer answers for its numbers being
    finite.
    """

    __slots__ = ()


def finite_json(
    document: object,
    *,
    indent: int | None = 2,
    levels: int | None = None,
    what: str = "The result",
) -> str:
    """Return ``document`` as JSON text, refusing NaN and infinity.

    Args:
        document: dicts (with string keys), lists, strings, numbers, booleans and None.
        indent: the indentation, as :func:`json.dumps` takes it.
        levels: with ``indent``, how many levels of containers are laid out over lines:
            a container deeper, or one holding no container, is one compact line (None:
            every level).
        what: names the document in the message ("The result").

    Returns:
        The JSON text (no trailing newline).

    Raises:
        ExportError: a number is NaN or infinite; the message names its place.
    """
    try:
        if indent is None or levels is None:
            return json.dumps(document, indent=indent, allow_nan=False)
        return _layered(document, levels, indent, 0)
    except ValueError as err:
        where, value = next(_non_finite(document, "$"), ("?", float("nan")))
        msg = (
            f"{what} holds {value!r} at {where}, a number JSON cannot carry: an input or "
            "option is too large to compute with (check the coordinates, units and the "
            "site transform), or this is a bug to report with the inputs."
        )
        raise ExportError(msg) from err


def _layered(value: object, levels: int, indent: int, depth: int) -> str:
    """Return ``value`` as JSON, its outer ``levels`` of containers over lines."""
    inner = "\n" + " " * (indent * (depth + 1))
    outer = "\n" + " " * (indent * depth)
    if isinstance(value, JSONItems):  # containers already, each one line
        if levels <= 0 or not value:
            return _compact(value)
        return "[" + inner + ("," + inner).join(value) + outer + "]"
    items = _items(value)
    if levels <= 0 or not any(isinstance(item, Mapping | list | tuple) for item in items):
        return _compact(value)
    if isinstance(value, Mapping):
        lines = [
            f"{json.dumps(key)}: {_layered(item, levels - 1, indent, depth + 1)}"
            for key, item in value.items()
        ]
        return "{" + inner + ("," + inner).join(lines) + outer + "}"
    lines = [_layered(item, levels - 1, indent, depth + 1) for item in items]
    return "[" + inner + ("," + inner).join(lines) + outer + "]"


def _compact(value: object) -> str:
    """Return ``value`` as one line of JSON, as :func:`json.dumps` does."""
    if isinstance(value, JSONItems):
        return "[" + ", ".join(value) + "]"
    if not _holds_items(value):
        return json.dumps(value, allow_nan=False)  # the C encoder: no indentation
    if isinstance(value, Mapping):
        pairs = [f"{json.dumps(key)}: {_compact(item)}" for key, item in value.items()]
        return "{" + ", ".join(pairs) + "}"
    return "[" + ", ".join(_compact(item) for item in _items(value)) + "]"


def _holds_items(value: object) -> bool:
    """Return whether ``value`` is or holds :class:`JSONItems` at any depth."""
    if isinstance(value, JSONItems):
        return True
    return any(
        _holds_items(item) for item in _items(value) if isinstance(item, Mapping | list | tuple)
    )


def _items(value: object) -> list[object]:
    """Return the values of a dict or the items of a list (nothing for anything else)."""
    if isinstance(value, Mapping):
        return list(value.values())
    if isinstance(value, list | tuple):
        return list(value)
    return []


def _non_finite(value: object, path: str) -> Iterator[tuple[str, float]]:
    """Yield (path, value) of every non-finite number (only walked once a dump failed)."""
    if isinstance(value, float) and not math.isfinite(value):
        yield path, value
    elif isinstance(value, Mapping):
        for key, item in value.items():
            yield from _non_finite(item, f"{path}.{key}")
    elif isinstance(value, list | tuple):
        for index, item in enumerate(value):
            yield from _non_finite(item, f"{path}[{index}]")
