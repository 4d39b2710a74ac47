"""What a command line with an unknown argument is told: one line, and the flag meant (issue 44).

argparse answers a mistyped flag (``--algin sim3``) with the whole usage (27 lines for
``loceval evaluate``) before "unrecognized arguments". Every ``loceval`` command answers
instead with one line naming the flag and the nearest valid one, found with :mod:`difflib`
among the command's own option strings (so the list can never go stale), and exits 1 like
any bad input. This module is pure Python: the parser imports it without numpy.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from typing import Final, NoReturn

__all__ = ["EXIT_INPUT", "fail", "nearest_option", "unknown_arguments"]

EXIT_INPUT: Final = 1
"""The exit code of bad input (a usage error is bad input, not a bug)."""

_CUTOFF: Final = 0.6
"""difflib's similarity below which no option is offered (its default)."""


def _flag(argument: str) -> str:
    """Return the flag of ``--flag=value``."""
    return argument.split("=", 1)[0]


def _is_flag(argument: str) -> bool:
    """Whether an argument looks like a flag (``-0.5`` is a number, not a flag)."""
    if not argument.startswith("-") or argument == "-":
        return False
    try:
        float(argument)
    except ValueError:
        return True
    return False


def nearest_option(parser: argparse.ArgumentParser, flag: str) -> str | None:
    """Return the parser's option string nearest to a mistyped ``flag``, or None.

    Long flags are compared with long flags (``--algin`` -> ``--align``), so a short
    option is offered only for a short mistype.
    """
    known = parser._option_string_actions  # noqa: SLF001  (argparse keeps them there)
    options = [o for o in known if o.startswith("--") == flag.startswith("--")]
    import difflib  # noqa: PLC0415  (a mistyped flag only)

    found = difflib.get_close_matches(flag, options, n=1, cutoff=_CUTOFF)
    return found[0] if found else None


def unknown_arguments(
    parser: argparse.ArgumentParser,
    extras: Sequence[str],
    hint: Callable[[str], str | None] | None = None,
) -> str:
    """Return the one-line message for the arguments ``parser`` did not take.

    Args:
        parser: the command's parser (its option strings are the valid ones).
        extras: the arguments it did not recognise, in order.
        hint: what to say about a flag instead of the nearest option (evo's flags name
            what loceval calls them), or None to fall back to the nearest option.
    """
    flags = list(dict.fromkeys(_flag(a) for a in extras if _is_flag(a)))
    if not flags:
        return f"unrecognized arguments: {' '.join(extras)}"
    said = [_about(parser, flag, hint) for flag in flags]
    if len(flags) == 1:
        return f"unknown option {flags[0]}; {said[0]}"
    listed = ", ".join(f"{flag} ({text})" for flag, text in zip(flags, said, strict=True))
    return f"unknown options {listed}"


def _about(
    parser: argparse.ArgumentParser, flag: str, hint: Callable[[str], str | None] | None
) -> str:
    """Return what to say about one unknown flag: the hint, the nearest option or --help."""
    special = hint(flag) if hint is not None else None
    if special is not None:
        return special
    near = nearest_option(parser, flag)
    return f"did you mean {near}?" if near else f"see {parser.prog} --help"


def fail(parser: argparse.ArgumentParser, message: str) -> NoReturn:
    """Print ``PROG: error: MESSAGE`` as one line and exit with :data:`EXIT_INPUT`."""
    parser.exit(EXIT_INPUT, f"{parser.prog}: error: {message}\n")
