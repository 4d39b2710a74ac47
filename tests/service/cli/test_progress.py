"""``loceval evaluate``'s progress: on a terminal's stderr only (issue 44, item 20).

Run as a user runs it, with stderr a pseudo-terminal (``pty``): the stages the service's
jobs report ("reading ...", "evaluating ...", "writing ...") and the share done appear; with
stderr a pipe, or with ``--json``, stderr stays empty (on main it was empty on a terminal
too: tens of seconds of silence on a large bag).
"""

from __future__ import annotations

import os
import pty
import select
import subprocess
import sys
import time
from pathlib import Path

import pytest

from service.cli.demo import write_demo_recording

_ROOT = Path(__file__).parents[3]


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Write the synthetic demo recording once."""
    return write_demo_recording(tmp_path_factory.mktemp("demo"))


def _argv(demo: dict[str, Path], *flags: str) -> list[str]:
    files = [str(demo["reference"]), str(demo["RTAB-Map"]), str(demo["ISAAC"])]
    return [sys.executable, "-m", "service.cli", "evaluate", *files, "--no-ci", *flags]


def _with_terminal_stderr(argv: list[str]) -> tuple[int, str, str]:
    """Run ``argv`` with stderr a pseudo-terminal; return its code, stdout and the terminal."""
    leader, follower = pty.openpty()
    env = {**os.environ, "PYTHONPATH": str(_ROOT), "COLUMNS": "100"}
    proc = subprocess.Popen(
        argv, cwd=_ROOT, env=env, stdout=subprocess.PIPE, stderr=follower, stdin=subprocess.DEVNULL
    )
    os.close(follower)
    seen = bytearray()
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:  # read until the command ends and nothing is left
        ready, _, _ = select.select([leader], [], [], 0.5)
        if not ready:
            if proc.poll() is not None:
                break
            continue
        try:
            chunk = os.read(leader, 65536)
        except OSError:  # the follower closed: the command ended, everything read
            break
        if not chunk:
            break
        seen.extend(chunk)
    out = proc.communicate(timeout=60)[0].decode()
    os.close(leader)
    return proc.returncode, out, seen.decode(errors="replace")


def test_a_terminal_shows_the_stages_and_the_share_done(demo: dict[str, Path]) -> None:
    """The bar names the reading and the evaluating with a percentage, then clears itself."""
    code, out, terminal = _with_terminal_stderr(_argv(demo))
    assert code == 0, terminal
    assert "reading " in terminal
    assert "evaluating" in terminal
    assert "%" in terminal
    assert "Traceback" not in terminal
    assert out.startswith("Reference ")  # the tables on stdout as before


def test_a_terminal_with_json_shows_nothing(demo: dict[str, Path]) -> None:
    """--json prints the document only: no bar even on a terminal."""
    code, out, terminal = _with_terminal_stderr(_argv(demo, "--json"))
    assert code == 0, terminal
    assert terminal == ""
    assert out.lstrip().startswith("{")


def test_without_a_terminal_stderr_stays_clean(demo: dict[str, Path]) -> None:
    """Piped (a log, CI): stderr is empty, stdout the tables."""
    env = {**os.environ, "PYTHONPATH": str(_ROOT)}
    proc = subprocess.run(
        _argv(demo), cwd=_ROOT, env=env, capture_output=True, text=True, check=False, timeout=300
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    assert proc.stdout.startswith("Reference ")
