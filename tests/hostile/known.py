"""Cases that fail today, each with the class of bug it shows and where it is being fixed.

Keys are ``(surface, case id)`` with surface ``cli`` or ``http``. :func:`tests.hostile.run.params`
marks them ``xfail(strict=True)``: when the fix is merged the case passes, the strict mark
fails the run, and the line here is deleted.
"""

from __future__ import annotations

from typing import Final

__all__ = ["KNOWN", "NOT_RUN"]

_BADCORE = "issue 16 class {}, fixed on branch badcore"
_BADHTTP = "issue 16 class {}, fixed on branch badhttp"

KNOWN: Final[dict[tuple[str, str], str]] = {
    ("cli", "euroc-header-only"): _BADCORE.format("EuRoC header-only"),
    ("cli", "euroc-trunc-first-line"): _BADCORE.format("EuRoC header-only"),
    ("cli", "zip-duplicate-member"): _BADCORE.format("zip errors quoting extraction paths"),
    ("cli", "option-site-1e308"): _BADCORE.format("site 1e308"),
    ("cli", "option-rpe-delta-tiny"): _BADCORE.format("rpe_delta tiny"),
    ("http", "option-rpe-delta-tiny"): _BADCORE.format("rpe_delta tiny"),
    ("http", "euroc-header-only"): _BADCORE.format("EuRoC header-only"),
    ("http", "euroc-trunc-first-line"): _BADCORE.format("EuRoC header-only"),
    ("http", "option-site-1e308"): _BADCORE.format("site 1e308"),
    **{
        ("http", case): _BADCORE.format("zip errors quoting extraction paths")
        for case in (
            "zip-duplicate-member",
            *(
                f"{fmt}-{edit}"
                for fmt in ("db3dir", "mcapdir")
                for edit in ("garbage-metadata", "no-storage", "escaping-metadata", "empty")
            ),
            "db3dir-trunc-half",
        )
    },
}
"""Reason per known failing ``(surface, case id)``."""

NOT_RUN: Final[frozenset[tuple[str, str]]] = frozenset(
    {("cli", "option-rpe-delta-tiny"), ("http", "option-rpe-delta-tiny")}
)
"""Known failures that are not run until fixed: an RPE delta that rounds to 0 ns loops
until memory runs out (minutes and gigabytes), which no test run can afford."""
