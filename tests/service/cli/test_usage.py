"""A mistyped flag gets one line naming the flag meant; ``loceval --help`` lists every command.

Issue 44, items 13 and 14: ``loceval evaluate ... --algin sim3`` printed 27 lines of usage
before "unrecognized arguments"; ``loceval --help``'s hand-written list of commands lacked
``storage``. Every command of the parser (walked, not listed here) is checked.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator

import pytest

from service.cli import main
from service.cli.parser import build_parser, command_names
from tests.cli_contract import error_line, run_cli


def _commands(
    parser: argparse.ArgumentParser, path: tuple[str, ...] = ()
) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """Yield ``(words, parser)`` of every command that runs (the leaves of the parser tree)."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield path, parser
        return
    for name, child in subs[0].choices.items():
        yield from _commands(child, (*path, name))


def _argv(words: tuple[str, ...], parser: argparse.ArgumentParser) -> list[str]:
    """The command's words with a value for each required argument."""
    argv = list(words)
    for action in parser._actions:
        if not action.option_strings and not isinstance(action, argparse._SubParsersAction):
            argv.append("x")
        elif action.required:
            argv += [action.option_strings[-1], "x"]
    return argv


def _mistyped(flag: str) -> str:
    """The flag with its last two letters swapped (``--json`` -> ``--jsno``)."""
    return flag[:-2] + flag[-1] + flag[-2]


COMMANDS = list(_commands(build_parser()))


def test_every_command_is_walked() -> None:
    """The walk reaches the nested commands too (keys create, storage migrate, ape tum)."""
    walked = {" ".join(words) for words, _ in COMMANDS}
    assert {"evaluate", "keys create", "storage migrate", "ape tum", "rpe bag2", "res"} <= walked


@pytest.mark.parametrize(("words", "parser"), COMMANDS, ids=[" ".join(w) for w, _ in COMMANDS])
def test_a_mistyped_flag_is_one_line_naming_the_flag_meant(
    words: tuple[str, ...], parser: argparse.ArgumentParser, capsys: pytest.CaptureFixture[str]
) -> None:
    """Each command: exit 1, one line ``PROG: error: unknown option X; did you mean Y?``."""
    flags = [
        f
        for a in parser._actions
        for f in a.option_strings
        if f.startswith("--") and len(f) > 4 and f not in {"--help", "--version"}
    ]
    typed = _mistyped(flags[0]) if flags else "--zzzzzz"
    with pytest.raises(SystemExit) as exc:
        main([*_argv(words, parser), typed, "1"])
    err = capsys.readouterr().err
    line = error_line(int(str(exc.value.code)), err)
    assert err == line + "\n", "one line, no usage"
    advice = f"did you mean {flags[0]}?" if flags else f"see {parser.prog} --help"
    assert line == f"{parser.prog}: error: unknown option {typed}; {advice}"


def test_the_issue_s_command_line() -> None:
    """``--algin sim3``: the one line the issue asks for, exit 1, as a user runs it."""
    proc = run_cli("evaluate", "gt.txt", "est.txt", "--algin", "sim3", timeout=60)
    assert proc.returncode == 1
    assert proc.stdout == ""
    assert proc.stderr == (
        "loceval evaluate: error: unknown option --algin; did you mean --align?\n"
    )


def test_a_flag_nothing_resembles_points_to_help(capsys: pytest.CaptureFixture[str]) -> None:
    """No near option: the line says where the flags are listed."""
    with pytest.raises(SystemExit):
        main(["inspect", "x", "--zzzzzz"])
    err = capsys.readouterr().err
    assert err == "loceval inspect: error: unknown option --zzzzzz; see loceval inspect --help\n"


def test_several_unknown_flags_are_named_in_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    """Two mistypes: both named with their nearest options, still one line."""
    with pytest.raises(SystemExit):
        main(["evaluate", "a", "b", "--algin", "sim3", "--jsno"])
    err = capsys.readouterr().err
    assert err == (
        "loceval evaluate: error: unknown options --algin (did you mean --align?), "
        "--jsno (did you mean --json?)\n"
    )


def test_a_negative_number_is_no_flag(capsys: pytest.CaptureFixture[str]) -> None:
    """A stray value like -0.5 is an unrecognised argument, not an "unknown option"."""
    with pytest.raises(SystemExit):
        main(["inspect", "x", "-0.5"])
    assert "unrecognized arguments: -0.5" in capsys.readouterr().err


def test_help_lists_every_command(capsys: pytest.CaptureFixture[str]) -> None:
    """``loceval --help``'s description names each command the parser has, storage included."""
    with pytest.raises(SystemExit):
        main(["--help"])
    out = " ".join(capsys.readouterr().out.split())
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert "storage" in sub.choices
    assert f"The loceval command line: {', '.join(sub.choices)}." in out


def _help(parser: argparse.ArgumentParser) -> str:
    return parser.format_help()


def _defaults(parser: argparse.ArgumentParser) -> dict[str, object]:
    """Every argument's default and the command's own (its handler), as parsing sets them."""
    return {**{a.dest: a.default for a in parser._actions}, **parser._defaults}


def test_the_command_table_names_every_command_in_the_help_order() -> None:
    """command_names() is the full parser's list of commands, in its order."""
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert command_names() == list(sub.choices)


@pytest.mark.parametrize("command", command_names())
def test_a_command_built_alone_parses_and_helps_as_in_the_full_parser(command: str) -> None:
    """build_parser(COMMAND) has COMMAND with the same flags, defaults and help as the full one."""
    full, alone = (
        next(a for a in p._actions if isinstance(a, argparse._SubParsersAction)).choices[command]
        for p in (build_parser(), build_parser(command))
    )
    assert _help(alone) == _help(full)
    assert _defaults(alone) == _defaults(full)
    assert build_parser(command).description == build_parser().description


def test_an_unknown_first_word_builds_every_command() -> None:
    """A mistyped command (or --help) gets the full parser, whose error lists every command."""
    sub = next(
        a for a in build_parser("evalute")._actions if isinstance(a, argparse._SubParsersAction)
    )
    assert list(sub.choices) == command_names()
