"""Every hostile case through the command line, in-process (``service.cli.main``).

The contract for each command: exit 0 or 1, never 2 (a bug) or an uncaught exception; on
exit 1 one ``loceval: error:`` line with a message; no traceback, no temporary folder and no
terminal escape sequence in what is printed. Valid inputs must exit 0.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from service.cli import main
from tests.cli_contract import ERROR_PREFIX, error_line
from tests.hostile.bases import write_companions
from tests.hostile.corpus import CASES, Case
from tests.hostile.run import assert_clean_text, cli_commands, params


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse: a usage error is exit 2
        code = exc.code if isinstance(exc.code, int) else 2
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("case", params(CASES, "cli"))
def test_cli_hostile_input(
    case: Case, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The case's commands exit 0 or 1 with a clean one-line error (0 for valid input)."""
    folder = tmp_path / "case"
    folder.mkdir()
    write_companions(folder, case.base.role)
    path = case.build(folder).relative_to(folder)
    monkeypatch.chdir(folder)
    for argv in cli_commands(case, path):
        code, out, err = _run(argv, capsys)
        shown = f"loceval {' '.join(argv)[:300]!r} -> {code}\n{err[-3000:]}"
        assert code in {0, 1}, shown
        if case.valid:
            assert code == 0, shown
        assert_clean_text(err, tmp_path)
        assert "\x1b" not in err, shown
        if code == 1:
            line = error_line(code, err, shown=shown)
            assert line.startswith(ERROR_PREFIX), shown
            assert len(line) > len(ERROR_PREFIX) + 10, shown
        else:
            assert out.strip(), shown
