"""What the command line prints: the one set of symbols, in ASCII where the terminal lacks it.

Issue 44, item 10: the tables said "<= 0.05 m" where the reports say "≤". The CLI writes
"±", "≤" and "→" as the reports do; on a terminal whose encoding cannot show them (an
ASCII or Latin-1 locale) it spells them "+/-", "<=" and "->" rather than "?".
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from service.cli.demo import write_demo_recording
from service.cli.output import shown_as

_ROOT = Path(__file__).parents[3]
TEXT = "≤ 0.05 m: 9.4 ± 0.4 ms, map → odom"


@pytest.mark.parametrize(
    ("encoding", "shown"),
    [
        ("utf-8", TEXT),
        ("ascii", "<= 0.05 m: 9.4 +/- 0.4 ms, map -> odom"),
        ("latin-1", "<= 0.05 m: 9.4 ± 0.4 ms, map -> odom"),  # Latin-1 has ± (0xB1)
    ],
)
def test_symbols_as_the_terminal_can_show_them(encoding: str, shown: str) -> None:
    """UTF-8 keeps the symbols; ASCII spells each; Latin-1 keeps only the one it has."""
    assert shown_as(TEXT, encoding) == shown


def test_the_tables_use_the_symbols_and_an_ascii_terminal_reads_them(tmp_path: Path) -> None:
    """The share rows say "≤ 0.05 m"; with PYTHONIOENCODING=ascii, "<= 0.05 m", never "?"."""
    demo = write_demo_recording(tmp_path)
    argv = [sys.executable, "-m", "service.cli", "evaluate", str(demo["reference"]),
            str(demo["ISAAC"]), "--no-ci"]  # fmt: skip
    outputs = {}
    for encoding in ("utf-8", "ascii"):
        env = {**os.environ, "PYTHONPATH": str(_ROOT), "PYTHONIOENCODING": encoding}
        proc = subprocess.run(
            argv, capture_output=True, check=False, cwd=_ROOT, env=env, timeout=300
        )
        assert proc.returncode == 0, proc.stderr
        outputs[encoding] = proc.stdout.decode(encoding)
    assert "≤ 0.05 m " in outputs["utf-8"]
    assert "<= 0.05 m " not in outputs["utf-8"]
    assert "<= 0.05 m " in outputs["ascii"]
    assert "?" not in outputs["ascii"]
