"""Cases that fail today, each with the class of bug it shows and where it is being fixed.

Keys are ``(surface, case id)`` with surface ``cli`` or ``http``. :func:`tests.hostile.run.params`
marks them ``xfail(strict=True)``: when the fix is merged the case passes, the strict mark
fails the run, and the line here is deleted.
"""

from __future__ import annotations

from typing import Final

__all__ = ["KNOWN", "NOT_RUN"]

KNOWN: Final[dict[tuple[str, str], str]] = {}
"""Reason per known failing ``(surface, case id)``."""

NOT_RUN: Final[frozenset[tuple[str, str]]] = frozenset()
"""Known failures that are not run until fixed (a case that would loop or exhaust memory)."""
