"""The stage and progress of a long command on a terminal's stderr (issue 44, item 20).

``loceval evaluate`` on a large bag said nothing for tens of seconds. On a terminal it now
shows what the page shows: the job's stage ("reading run.mcap", "evaluating slam", "writing
report.pdf") and the share done, from the progress events the service's jobs report
(:func:`service.jobs.runner.run_job`'s callback), drawn by tqdm on one line that is cleared
at the end. When stderr is not a terminal (a pipe, a log, CI) or with ``--json``, nothing is
written: the output stays what it was.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator
from typing import TYPE_CHECKING, Final, TextIO

from loceval.core.display import display_text

if TYPE_CHECKING:
    from loceval.evaluation import ProgressCallback

__all__ = ["terminal_progress"]

_STEPS: Final = 1000
"""The bar's resolution: a thousandth of the job."""

_FORMAT: Final = "{desc} {percentage:3.0f}% |{bar}| {elapsed}"

_DEFAULT_SIZE: Final = (80, 24)


@contextlib.contextmanager
def terminal_progress(
    *, quiet: bool = False, stream: TextIO | None = None
) -> Iterator[ProgressCallback | None]:
    """Yield a progress callback drawing on ``stream`` (stderr), or None where none is due.

    Args:
        quiet: draw nothing (``--json``: the output is a document).
        stream: where to draw; stderr by default. Nothing is drawn unless it is a terminal.
    """
    out = stream or sys.stderr
    if quiet or not _is_terminal(out):
        yield None
        return
    from tqdm import tqdm  # noqa: PLC0415  (only on a terminal)

    columns, lines = _size(out)
    bar = tqdm(
        total=_STEPS,
        file=out,
        leave=False,
        ncols=columns,
        nrows=lines,  # tqdm hides a bar below the terminal's last row: 0 rows hid it
        bar_format=_FORMAT,
        mininterval=0.2,
    )

    def report(stage: str, fraction: float) -> None:
        bar.set_description_str(display_text(stage), refresh=False)
        bar.n = min(_STEPS, max(0, round(fraction * _STEPS)))
        bar.refresh()

    try:
        yield report
    finally:
        bar.close()


def _size(stream: TextIO) -> tuple[int, int]:
    """The terminal's columns and lines; 80 x 24 where it reports none (a new pty: 0 x 0)."""
    try:
        size = os.get_terminal_size(stream.fileno())
    except (AttributeError, OSError, ValueError):
        return _DEFAULT_SIZE
    return (
        size.columns if size.columns > 0 else _DEFAULT_SIZE[0],
        size.lines if size.lines > 0 else _DEFAULT_SIZE[1],
    )


def _is_terminal(stream: TextIO) -> bool:
    """Whether ``stream`` is a terminal (False for a closed or fake stream)."""
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False
