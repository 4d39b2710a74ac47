"""The ``loceval`` command line: evaluate, inspect, demo, report, serve, worker, keys.

A :class:`~loceval.errors.LocevalError` prints its message and exits 1 (bad input, no
traceback); an error about an option is prefixed with the option's flag (``--max-dt: ...``).
Running out of memory exits 1 too, with what to do about it.
The message is scrubbed of loceval's temporary folders (:func:`service.redact.scrub`) and
printed without control characters (:func:`service.cli.output.emit`).
A reader that closes the pipe early (``| head``) ends the command quietly (exit 141).
Anything else is a bug: the traceback is printed and the exit code is 2.
An evaluation whose gate closes (``--fail-on fail,undecided,worse``: a condition holds)
exits 3, its last line saying why (:func:`service.cli.evaluate.gate_exit`); 0 is done.

Each command lives in its own module, imported only when that command runs: ``loceval
--help`` loads the parser and the options table, not numpy, pydantic or the service.
"""

from __future__ import annotations

import gc
import importlib
import os
import sys
import traceback
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, cast

from loceval.errors import LocevalError
from service.cli.output import emit
from service.cli.parser import EXIT_BUG, EXIT_INPUT, build_parser

if TYPE_CHECKING:
    import argparse

__all__ = ["OUT_OF_MEMORY", "main", "run"]

OUT_OF_MEMORY = (
    "The command ran out of memory and stopped; evaluate shorter recordings or fewer "
    "estimates, or use coarser options (a larger --rpe-delta, fewer --formats)."
)
"""The message of a command that ran out of memory (a very small --rpe-delta, say)."""


EXIT_BROKEN_PIPE = 141
"""The shell's code for a command whose reader closed the pipe (128 + SIGPIPE)."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit code."""
    try:
        words = sys.argv[1:] if argv is None else list(argv)
        args = build_parser(words[0] if words else None).parse_args(words)
        return int(_handler(args.handler)(args))
    except LocevalError as err:
        from service.redact import scrub  # noqa: PLC0415  (errors only: it loads tempfile)

        emit(f"loceval: error: {scrub(describe(err))}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # the reader left (`loceval inspect FILE | head`): no bug
        # Point stdout at /dev/null so the interpreter's final flush cannot fail again.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except MemoryError:  # the input, not a bug: say what to do instead of a traceback
        print(f"loceval: error: {OUT_OF_MEMORY}", file=sys.stderr)  # noqa: T201
        return EXIT_INPUT
    except Exception:  # noqa: BLE001  (the documented bug path: traceback, exit 2)
        traceback.print_exc()
        print(  # noqa: T201
            "loceval: internal error; this is a bug, please report it with the traceback above.",
            file=sys.stderr,
        )
        return EXIT_BUG


def run() -> int:
    """Run the ``loceval`` command (:func:`main`) in a process that ends with it.

    When the process exits, the interpreter's collector walks every object still alive
    (numpy's, every module's, the evaluation's) to find garbage in reference cycles: about
    0.03 s of CPU after a 200,000-pose evaluation, a twentieth of the whole command, for
    memory the process returns to the system anyway. Freezing them (``gc.freeze``) leaves
    them out of that walk; ``atexit`` handlers still run, and objects freed by their
    reference counts (open files among them) are still closed. Tests call :func:`main`,
    which freezes nothing.
    """
    code = main()
    gc.freeze()
    return code


def describe(err: LocevalError) -> str:
    """Return the error's message, prefixed with the flag of the option at fault, if any."""
    if err.option is None:
        return str(err)
    from loceval.options import option  # noqa: PLC0415

    flag = option(err.option).flag
    text = f"{flag}: {err}"
    if err.suggest is not None:
        text += f" Use {flag} {err.suggest}."
    return text


def _handler(target: str) -> Callable[[argparse.Namespace], int]:
    """Import ``module:function`` of a command (each command's libraries load on use)."""
    module_name, _, name = target.partition(":")
    return cast(
        "Callable[[argparse.Namespace], int]", getattr(importlib.import_module(module_name), name)
    )
