"""Errors of the exporters (subclasses of the core's base, so every front door maps them)."""

from __future__ import annotations

from typing import ClassVar

from loceval.errors import InputError, LocevalError

__all__ = ["ExportError", "ExportOptionsError", "ExportUnavailableError"]


class ExportError(LocevalError):
    """A file could not be produced (a CAD library refused the geometry, a render failed)."""

    code: ClassVar[str] = "export.failed"


class ExportOptionsError(InputError):
    """Export options a user gave that cannot be used (units, site transform, building)."""

    code: ClassVar[str] = "export.options"


class ExportUnavailableError(ExportError):
    """The library a format needs is not installed."""

    code: ClassVar[str] = "export.unavailable"
