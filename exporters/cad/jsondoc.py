"""JSON documents with finite numbers only: the one writer of result documents.

JSON has no NaN or infinity. A document that holds one (an input large enough to overflow
a computation) is refused with a message naming where, never written as invalid JSON.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Mapping

from exporters.errors import ExportError

__all__ = ["finite_json"]


def finite_json(document: object, *, indent: int | None = 2, what: str = "The result") -> str:
    """Return ``document`` as JSON text, refusing NaN and infinity.

    Args:
        document: dicts, lists, strings, numbers, booleans and None.
        indent: the indentation, as :func:`json.dumps` takes it.
        what: names the document in the message ("The result").

    Returns:
        The JSON text (no trailing newline).

    Raises:
        ExportError: a number is NaN or infinite; the message names its place.
    """
    try:
        return json.dumps(document, indent=indent, allow_nan=False)
    except ValueError as err:
        where, value = next(_non_finite(document, "$"), ("?", float("nan")))
        msg = (
            f"{what} holds {value!r} at {where}, a number JSON cannot carry: an input or "
            "option is too large to compute with (check the coordinates, units and the "
            "site transform), or this is a bug to report with the inputs."
        )
        raise ExportError(msg) from err


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
