"""The README is a first screen, and the docs it links hold the reference, following the code.

The README (under 200 lines) says what loceval is, shows a picture, gives the two commands and
where to click; every other fact moved to a page of ``docs/`` it links. These tests keep the
lists of those pages in step with the code: every artifact, and the tests' data folder.
"""

from __future__ import annotations

import re
from pathlib import Path

from exporters import ARTIFACTS

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
DOCS = ROOT / "docs"
API = (DOCS / "api.md").read_text(encoding="utf-8")
FILES = (DOCS / "files.md").read_text(encoding="utf-8")
DEVELOPMENT = (DOCS / "development.md").read_text(encoding="utf-8")


def _section(text: str, title: str) -> str:
    """The text of a page's section, from its heading to the next heading."""
    start = text.index(f"\n{title}\n")
    end = text.find("\n#", start + len(title) + 2)
    return text[start : end if end >= 0 else None]


def test_the_artifact_download_row_names_every_artifact() -> None:
    """The API table's artifact route lists each file an evaluation can make."""
    (row,) = [line for line in API.splitlines() if "/artifacts/{name}`" in line]
    listed = re.findall(r"`([a-z0-9_.]+\.[a-z0-9]+)`", row)
    assert [name for name in ARTIFACTS if name not in listed] == []


def test_the_files_table_has_a_row_per_artifact() -> None:
    """Under "The files" (docs/files.md) each artifact has its row (paths.ifc among them)."""
    table = _section(FILES, "## The files")
    first_cells = [line.split("|")[1] for line in table.splitlines() if line.startswith("| `")]
    described = {name for cell in first_cells for name in re.findall(r"`([^`]+)`", cell)}
    assert [name for name in ARTIFACTS if name not in described] == []


def test_the_public_data_variable_is_documented() -> None:
    """LOCEVAL_PUBLIC_DATA, which the tests read, is in docs/development.md with its default."""
    conftest = (Path(__file__).parent / "conftest.py").read_text(encoding="utf-8")
    assert '"LOCEVAL_PUBLIC_DATA"' in conftest  # the variable the tests read
    paragraph = next(p for p in DEVELOPMENT.split("\n\n") if "LOCEVAL_PUBLIC_DATA" in p)
    assert "../shared/data/public" in paragraph
    assert "skip" in paragraph


def test_the_readme_is_a_first_screen() -> None:
    """Title first, under 200 lines, the two commands of the Makefile and .ci/run, a picture."""
    lines = README.splitlines()
    assert lines[0] == "# loceval"  # no code block before the title
    assert len(lines) < 200
    (block,) = re.findall(r"## Two commands\n\n```sh\n(.*?)```", README, flags=re.DOTALL)
    assert [line.split("#")[0].strip() for line in block.splitlines()] == [
        "make serve",
        "make test",
    ]
    assert (ROOT / ".ci" / "run").read_text(encoding="utf-8").rstrip().endswith("make test")
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    assert re.search(r"^serve: setup$", makefile, flags=re.MULTILINE)
    assert re.search(r"^test: lint typecheck pytest$", makefile, flags=re.MULTILINE)
    (image,) = re.findall(r"!\[[^\]]+\]\((docs/images/[^)]+\.png)\)", README)
    assert (ROOT / image).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (ROOT / image).stat().st_size < 300_000
