"""The command line's contract for bad input, shared by the CLI tests and the hostile corpus.

Bad input to a ``loceval`` command exits 1 and prints exactly one error line, no traceback;
:func:`error_line` checks that and returns the line for the test's own checks of what it
says. :func:`run_cli` runs the CLI as a user runs it: a subprocess.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Final

import service

__all__ = ["ERROR_PREFIX", "cli_error_line", "error_line", "run_cli"]

_ROOT: Final = Path(service.__file__).resolve().parents[1]
ERROR_PREFIX: Final = "loceval: error: "


def run_cli(*argv: str | Path, timeout: float) -> subprocess.CompletedProcess[str]:
    """Run ``python -m service.cli ARGV`` from the project root; return what it did."""
    return subprocess.run(
        [sys.executable, "-m", "service.cli", *map(str, argv)],
        capture_output=True, text=True, check=False, timeout=timeout, cwd=_ROOT,
        env={**os.environ, "PYTHONPATH": str(_ROOT)},
    )  # fmt: skip


def error_line(code: int, stderr: str, *, shown: str | None = None) -> str:
    """Assert the input-error contract (exit 1, no traceback, one error line); return it.

    The error line is the one line of ``stderr`` with ``error:`` in it: ``loceval: error:``
    for the core's and the CLI's own checks, ``loceval evaluate: error:`` for argparse's.
    ``shown`` is what a failed assertion prints (``stderr`` unless given).
    """
    context = stderr if shown is None else shown
    assert "Traceback" not in stderr, context
    assert code == 1, context
    lines = [line for line in stderr.splitlines() if "error:" in line]
    assert len(lines) == 1, context
    return lines[0]


def cli_error_line(proc: subprocess.CompletedProcess[str]) -> str:
    """:func:`error_line` of a finished ``loceval`` subprocess (its exit code and stderr)."""
    return error_line(proc.returncode, proc.stderr)
