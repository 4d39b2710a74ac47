"""Artifact names: file names and the format aliases ``--formats`` accepts."""

from __future__ import annotations

import pytest

from exporters import ARTIFACT_ALIASES, ARTIFACTS, artifact_name
from exporters.errors import ExportOptionsError


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("dxf", "paths.dxf"),
        ("pdf", "report.pdf"),
        ("glb", "paths.glb"),
        ("gltf", "paths.glb"),
        ("3dm", "paths.3dm"),
        ("3dm.json", "paths.3dm.json"),
        ("html", "report.html"),
        ("csv", "errors.csv"),
        ("json", "result.json"),
        (" .DXF ", "paths.dxf"),
        ("paths.dxf", "paths.dxf"),
        ("Report.PDF", "report.pdf"),
    ],
)
def test_aliases_and_file_names(text: str, expected: str) -> None:
    """A format name or a file name, in any case, names its artifact."""
    assert artifact_name(text) == expected


def test_every_alias_names_an_artifact() -> None:
    """Aliases point at real artifacts, and every artifact has an alias."""
    assert set(ARTIFACT_ALIASES.values()) == set(ARTIFACTS)


@pytest.mark.parametrize("text", ["dwg", "", "paths", "report"])
def test_unknown_names_list_the_choices(text: str) -> None:
    """An unknown name is an options error on 'formats' listing file names and formats."""
    with pytest.raises(
        ExportOptionsError, match=r"No output format named .*paths\.dxf.*dxf \(paths\.dxf\)"
    ) as err:
        artifact_name(text)
    assert err.value.option == "formats"
    assert "--formats" not in str(err.value)
