"""How a case is given to loceval: its command lines, its API requests, and what must hold.

The command lines name every file relative to the case folder (the tests run them with that
folder as the working directory), so any absolute ``/tmp/...`` text in the output is a
server or extraction path that leaked, not the user's own argument echoed back.
"""

from __future__ import annotations

import io
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Final

import pytest

from tests.hostile.bases import ANCHORS, CP_ESTIMATE, CP_SURVEY, ESTIMATE, RANGES, WALK, Role
from tests.hostile.corpus import Case
from tests.hostile.known import KNOWN, NOT_RUN

__all__ = [
    "CHEAP",
    "assert_clean_text",
    "cli_commands",
    "params",
    "upload_payload",
]

CHEAP: Final[Mapping[str, Any]] = {"formats": ["result.json"]}
"""API options of an evaluation that writes only its result."""


def params(cases: list[Case], surface: str) -> list[Any]:
    """Return ``pytest.param`` per case, ``xfail(strict)`` for known failures on ``surface``."""
    out = []
    for case in cases:
        reason = KNOWN.get((surface, case.id))
        run = (surface, case.id) not in NOT_RUN
        marks = [pytest.mark.xfail(strict=True, reason=reason, run=run)] if reason else []
        out.append(pytest.param(case, id=case.id, marks=marks))
    return out


def cli_commands(case: Case, path: Path) -> list[list[str]]:
    """Return the ``loceval`` argument lists that read the case's input (relative ``path``)."""
    role = case.base.role
    source = f"{path}{case.base.selector}"
    extra = list(case.args)
    if "--formats" in extra:
        extra += ["--out", "out"]
    inspect = ["inspect", str(path), "--json"]
    if role is Role.TRAJECTORY:
        return [inspect, ["evaluate", source, ESTIMATE, "--json", *extra]]
    if role is Role.POINTS:
        return [inspect, ["evaluate", source, CP_ESTIMATE, "--align", "none", "--json"]]
    if role is Role.VISITS:
        evaluate = ["evaluate", CP_SURVEY, CP_ESTIMATE, "--align", "none", "--visits", str(path)]
        return [inspect, [*evaluate, "--json"]]
    if role is Role.BUILDING:
        # a mesh is read for the glTF scene, a DXF floor plan only for the report's plan views
        artifact = "report.html" if path.suffix == ".dxf" else "paths.glb"
        building = ["--building", str(path), "--formats", artifact, "--out", "out"]
        return [["evaluate", "ref.txt", ESTIMATE, *building]]
    anchors, ranges = (str(path), RANGES) if role is Role.ANCHORS else (ANCHORS, str(path))
    ranging = ["ranging", WALK, "--anchors", anchors, "--ranges", ranges, "--json"]
    return [inspect, ranging]


def upload_payload(path: Path) -> tuple[str, bytes]:
    """Return the file name and bytes to upload: a folder (a ROS 2 bag) is zipped."""
    if path.is_file():
        return path.name, path.read_bytes()
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        for file in sorted(path.rglob("*")):
            if file.is_file():
                archive.write(file, str(file.relative_to(path.parent)))
    return f"{path.name}.zip", buffer.getvalue()


def assert_clean_text(text: str, *folders: Path) -> None:
    """Assert a user-facing text names no temporary or server folder and has no traceback."""
    assert "Traceback" not in text, text
    assert "/tmp/" not in text, text  # noqa: S108  (no temporary folder is named)
    for folder in folders:
        assert str(folder) not in text, (str(folder), text)
        assert str(folder.resolve()) not in text, (str(folder), text)
