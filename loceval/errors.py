"""Typed errors: every error loceval raises on purpose derives from :class:`LocevalError`.

Messages are one sentence that names the offending value and says what to do; the CLI
prints them without a traceback (exit code 1) and the service maps them to 4xx problems.
"""

from __future__ import annotations

import copy
from typing import ClassVar, Self

__all__ = [
    "AlignmentError",
    "AssociationError",
    "InputError",
    "LocevalError",
    "MetricError",
    "ReaderError",
    "TrajectoryError",
]


class LocevalError(Exception):
    """Base for every error this project raises on purpose.

    Args:
        message: one sentence that names the offending value and says what to do. It names
            no command-line flag: an error about an option carries the option's key in
            ``option`` and each front door names that option its own way (the CLI as
            ``--max-dt``, the HTTP API as ``options.max_dt_s``).
        option: the key of the evaluation option at fault (``"max_dt_s"``), if any.
        suggest: the value of that option that would fix it (``"receive"``), if one would;
            each front door spells the setting out in its own words.
    """

    code: ClassVar[str] = "error"

    def __init__(
        self, message: str = "", *, option: str | None = None, suggest: str | None = None
    ) -> None:
        """Keep the message, the option's key and the value to suggest."""
        super().__init__(message)
        self.option = option
        self.suggest = suggest

    def reworded(self, message: str) -> Self:
        """Return the same error (its class, code and cause) saying ``message`` instead.

        For a front door that names the option in its own words inside the message (a
        template's ``options.max_dt_s``): ``option`` and ``suggest`` are dropped, so it is
        not named a second time.
        """
        clone = copy.copy(self)
        clone.args = (message,)
        clone.option = None
        clone.suggest = None
        return clone


class InputError(LocevalError):
    """User data or options that cannot be used."""

    code: ClassVar[str] = "input.invalid"


class ReaderError(InputError):
    """A file, bag, topic or column that cannot be read."""

    code: ClassVar[str] = "input.unreadable"


class TrajectoryError(InputError):
    """Arrays that do not form a valid trajectory (shape, NaN, too few poses)."""

    code: ClassVar[str] = "input.trajectory"


class AssociationError(LocevalError):
    """Reference and estimate cannot be matched in time."""

    code: ClassVar[str] = "association.no_matches"


class AlignmentError(LocevalError):
    """The spatial alignment is undetermined (degenerate geometry, too few poses)."""

    code: ClassVar[str] = "alignment.degenerate"


class MetricError(LocevalError):
    """A metric cannot be computed with the given parameters."""

    code: ClassVar[str] = "metric.invalid"
