"""A report of many estimates sets its tables of a column per estimate a few at a time.

Fifteen estimates' columns in one A4 table squeezed each figure into a column two letters
wide ("-14960." over "00 ms"); the PDF now sets such a table (the shares within each
distance, the alignment, the statistics, the clocks) as several tables of at most four
estimates, one under the other, each with its row labels. Read back with pdftotext.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import numpy as np

from exporters import write_artifacts
from exporters.options import ExportOptions
from loceval.evaluation import EvaluationConfig, Tolerance, evaluate
from tests.conftest import require_tool
from tests.exporters.conftest import noisy, walk

ESTIMATES = 9


def test_nine_estimates_are_set_four_to_a_table(tmp_path: Path) -> None:
    """No printed line names more than four estimates; every estimate's figures are there."""
    tool = require_tool("pdftotext")
    rng = np.random.default_rng(4)
    truth = walk(rng, n=1500)
    estimates = [
        noisy(rng, truth, every=2, sigma=0.01, drift=0.02 * k, name=f"run{k}")
        for k in range(ESTIMATES)
    ]
    result = evaluate(truth, estimates, EvaluationConfig(tolerance=Tolerance(0.05, 0.95)))
    write_artifacts(result, tmp_path, ExportOptions(title="Nine runs"), names=["report.pdf"])
    text = subprocess.run(
        [tool, "-layout", str(tmp_path / "report.pdf"), "-"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    lines = text.splitlines()
    # the statistics: a header per part, each naming at most four, all nine named once a table
    heads = [line for line in lines if re.search(r"error metric\s+run\d", line)]
    assert len(heads) >= 2 * -(-ESTIMATES // 4)  # translation and rotation, 3 parts each
    assert max(len(re.findall(r"\brun\d\b", line)) for line in heads) <= 4
    named = {name for line in heads for name in re.findall(r"\brun\d\b", line)}
    assert named == {f"run{k}" for k in range(ESTIMATES)}
    # the alignment's method row and the clocks' first row: four values a line at most
    methods = [line.split() for line in lines if line.strip().startswith("method ")]
    assert sum(len(words) - 1 for words in methods) == ESTIMATES
    assert max(len(words) - 1 for words in methods) <= 4
    given = [line for line in lines if line.strip().startswith("Time offset given")]
    assert sum(line.count(" ms") for line in given) == ESTIMATES
    assert max(line.count(" ms") for line in given) <= 4
