"""The README's lists follow the code: every artifact, and the tests' data folder."""

from __future__ import annotations

import re
from pathlib import Path

from exporters import ARTIFACTS

README = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")


def _section(title: str) -> str:
    """The text of a README section, from its heading to the next heading."""
    start = README.index(f"\n{title}\n")
    end = README.find("\n#", start + len(title) + 2)
    return README[start : end if end >= 0 else None]


def test_the_artifact_download_row_names_every_artifact() -> None:
    """The API table's artifact route lists each file an evaluation can make."""
    (row,) = [line for line in README.splitlines() if "/artifacts/{name}`" in line]
    listed = re.findall(r"`([a-z0-9_.]+\.[a-z0-9]+)`", row)
    assert [name for name in ARTIFACTS if name not in listed] == []


def test_the_files_table_has_a_row_per_artifact() -> None:
    """Under "Reports and CAD files" each artifact has its row (paths.ifc among them)."""
    table = _section("### Reports and CAD files")
    first_cells = [line.split("|")[1] for line in table.splitlines() if line.startswith("| `")]
    described = {name for cell in first_cells for name in re.findall(r"`([^`]+)`", cell)}
    assert [name for name in ARTIFACTS if name not in described] == []


def test_the_public_data_variable_is_documented() -> None:
    """LOCEVAL_PUBLIC_DATA, which the tests read, is in the README with its default."""
    conftest = (Path(__file__).parent / "conftest.py").read_text(encoding="utf-8")
    assert '"LOCEVAL_PUBLIC_DATA"' in conftest  # the variable the tests read
    paragraph = next(p for p in README.split("\n\n") if "LOCEVAL_PUBLIC_DATA" in p)
    assert "../shared/data/public" in paragraph
    assert "skip" in paragraph
