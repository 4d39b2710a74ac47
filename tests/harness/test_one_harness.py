"""The benchmarks start their servers through the harness: no copy of test code in them."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _copy(folder: str, into: Path) -> None:
    for path in (ROOT / folder).rglob("*.py"):
        target = into / path.relative_to(ROOT)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, target)


def test_duplicates_finds_no_pair_between_benchmarks_and_tests(tmp_path: Path) -> None:
    """``duplicates`` (this machine's tool) pairs no place of benchmarks/ with one of tests/."""
    tool = shutil.which("duplicates")
    if tool is None:
        pytest.skip("the duplicates tool is not on PATH (a tool of the development machine)")
    for folder in ("benchmarks", "tests"):
        _copy(folder, tmp_path)
    done = subprocess.run(
        [tool, "--repo", str(tmp_path), "--most", "200", "--seconds", "120"],
        capture_output=True, text=True, check=True, timeout=300,
    )  # fmt: skip
    report = done.stdout
    assert "incomplete:" not in report, report
    assert "more pairs)" not in report, report  # every pair was listed
    crossing = [
        row
        for row in report.splitlines()
        if row.startswith("D") and "benchmarks/" in row and "tests/" in row
    ]
    assert crossing == []
