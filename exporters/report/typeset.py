"""Typesetting a report's view model as an A4 PDF with Typst: no system library.

The PDF of a report, of a control-point report and of a summary is typeset by Typst (the
``typst`` wheel: the compiler itself, with its own fonts) from a ``.typ`` template beside the
HTML one, reading the same view model the Jinja2 template reads. The view model goes to the
template as one JSON document (:func:`typst_document`): every dataclass a dictionary of its
fields, tuples lists; so the template shows the figures, numbers and sentences the HTML
shows and computes none of its own. Each figure (an SVG ``data:`` URI in the view) goes as
its own input, and the template places it as a vector drawing.

The text is DejaVu Sans, the font of the figures, taken from matplotlib's own font folder:
the same glyphs on every machine, embedded (subset) in the PDF; the system's fonts are
never looked at. Nothing is read from the network or from outside the template folder.
"""

from __future__ import annotations

import base64
import dataclasses
import functools
import json
import logging
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Final

from exporters.errors import ExportError, ExportUnavailableError
from exporters.plots.svg.metrics import typst_fonts

if TYPE_CHECKING:
    pass

__all__ = [
    "DOCUMENT_INPUT",
    "check_typst",
    "preload_fonts",
    "typeset_pdf",
    "typst_available",
    "typst_document",
]

logger = logging.getLogger(__name__)

DOCUMENT_INPUT: Final = "document"
"""The ``sys.inputs`` key of the view model's JSON (``json(bytes(sys.inputs.document))``)."""
_SVG_URI: Final = "data:image/svg+xml;base64,"
_IMAGE_KEY: Final = "image-"
"""A figure's ``sys.inputs`` key: ``image-1``, ``image-2``, ... (the view holds the key)."""


def typst_document(view: object) -> tuple[str, dict[str, str]]:
    """Return a view model as the template's JSON and its figures as separate inputs.

    Dataclasses become objects of their fields, mappings objects, tuples and lists arrays;
    strings, numbers, booleans and None stay as they are. An SVG ``data:`` URI (a figure)
    becomes the key of an input holding the SVG document, which the template reads with
    ``image(bytes(sys.inputs.at(key)))``.

    Args:
        view: the view model (a dataclass).

    Returns:
        ``(json, figures)``: the document and the figures by key.

    Raises:
        TypeError: the view holds a value of another kind (a bug in the view model).
    """
    figures: dict[str, str] = {}

    def plain(value: object) -> object:
        if isinstance(value, str):
            if value.startswith(_SVG_URI):
                key = f"{_IMAGE_KEY}{len(figures) + 1}"
                figures[key] = base64.b64decode(value[len(_SVG_URI) :]).decode("utf-8")
                return key
            return value
        if value is None or isinstance(value, bool | int | float):
            return value
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
        if isinstance(value, Mapping):
            return {str(k): plain(v) for k, v in value.items()}
        if isinstance(value, tuple | list):
            return [plain(v) for v in value]
        msg = f"A report view holds {type(value).__name__!r}, which the PDF cannot show."
        raise TypeError(msg)

    document = json.dumps(plain(view), ensure_ascii=False, allow_nan=False)
    return document, figures


@functools.cache
def check_typst() -> None:
    """Import the Typst binding once; raise what to install when it is missing.

    Raises:
        ExportUnavailableError: the typst package is not installed.
    """
    try:
        import typst  # noqa: F401, PLC0415  (loceval[report]; imported with the first PDF)
    except ImportError as err:
        msg = f"PDF reports need the typst package; install loceval[report] ({err})."
        raise ExportUnavailableError(msg) from err


def preload_fonts() -> None:
    """Read the fonts now (the service's job processes start with them read)."""
    typst_fonts()


def typst_available() -> bool:
    """Tell whether this process can typeset PDFs (the typst package imports)."""
    try:
        check_typst()
    except ExportUnavailableError:
        return False
    return True


def typeset_pdf(template: Path, view: object, *, label: str) -> bytes:
    """Typeset a view model with a Typst template; return the PDF.

    Args:
        template: the ``.typ`` file; its folder is the root the template may read from.
        view: the view model (see :func:`typst_document`).
        label: names the template in messages (``report``, ``summary``).

    Returns:
        The PDF (A4 pages, text selectable, fonts embedded, figures as vectors).

    Raises:
        ExportUnavailableError: the typst package is missing.
        ExportError: the template is missing or failed.
    """
    check_typst()
    import typst  # noqa: PLC0415

    if not template.is_file():
        msg = f"No {label} template {template.name!r} in {str(template.parent)!r}."
        raise ExportError(msg)
    document, figures = typst_document(view)
    inputs = {**figures, DOCUMENT_INPUT: document}
    try:
        pdf, warnings = typst.compile_with_warnings(
            template,
            root=template.parent,
            font_paths=typst_fonts(),
            sys_inputs=inputs,
            format="pdf",
        )
    except typst.TypstError as err:
        message = err.message
        hints = "; ".join(err.hints or ())
        msg = f"The {label} template {str(template)!r} failed: {message}" + (
            f" ({hints})." if hints else "."
        )
        raise ExportError(msg) from err
    for warning in warnings:
        logger.warning("The %s template %s: %s", label, template, warning.message)
    return bytes(pdf)
