"""Dependency direction: the core never pulls in web, templating or CAD libraries."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

BANNED = ("fastapi", "pydantic", "ezdxf", "trimesh", "rhino3dm", "weasyprint", "jinja2",
          "matplotlib", "rosbags", "exporters", "service")  # fmt: skip


@pytest.mark.parametrize(
    ("module", "allowed"),
    [
        ("loceval", ()),
        ("loceval.evaluation", ()),
        ("loceval.readers", ()),
        ("exporters", ("exporters",)),
        ("service.cli", ("exporters", "service")),
    ],
)
def test_import_pulls_in_no_banned_module(module: str, allowed: tuple[str, ...]) -> None:
    """Importing a layer loads none of the heavy or upward modules (lazy imports only)."""
    code = (
        f"import json, sys; import {module}; "
        "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd="."
    )
    loaded = set(json.loads(out.stdout))
    assert not (loaded & (set(BANNED) - set(allowed)))
