"""The report templates: compiled once per folder and process, edits still picked up."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from exporters.errors import ExportError
from exporters.report import DEFAULT_TEMPLATES_DIR
from exporters.report.render import preload_templates, render_template


def _render(folder: Path, **context: object) -> bytes:
    return render_template(folder, "t.j2", label="test", requirement="this test", **context)


def test_an_edited_template_is_rendered_as_edited(tmp_path: Path) -> None:
    """The folder's environment is kept, and it notices a template changed on disk."""
    template = tmp_path / "t.j2"
    template.write_text("first {{ x }}\n")
    assert _render(tmp_path, x=1) == b"first 1\n"
    assert _render(tmp_path, x=2) == b"first 2\n"  # the compiled template, reused

    template.write_text("second {{ x }}\n")
    stat = template.stat()
    os.utime(template, ns=(stat.st_atime_ns, stat.st_mtime_ns + 2_000_000_000))
    assert _render(tmp_path, x=3) == b"second 3\n"


def test_a_broken_template_is_an_export_error_naming_its_folder(tmp_path: Path) -> None:
    """A template that does not compile fails its render, every time, with the folder named."""
    (tmp_path / "t.j2").write_text("{% if %}\n")
    for _ in range(2):
        with pytest.raises(ExportError, match="test template in") as caught:
            _render(tmp_path)
        assert str(tmp_path) in str(caught.value)


def test_preloading_compiles_every_report_template_and_skips_a_broken_one(tmp_path: Path) -> None:
    """Preloading the repository's folder compiles its report templates; a folder with a
    broken one is preloaded without error, and the report using it still fails when rendered.
    """
    script = (
        "from exporters.report import render\n"
        "render.preload_templates()\n"
        "env = render._environment(render.DEFAULT_TEMPLATES_DIR)\n"
        "print(len(env.cache))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True, timeout=120
    )
    folder = DEFAULT_TEMPLATES_DIR
    templates = [*folder.glob("*.j2"), *folder.glob("_partials/*.j2")]
    assert int(out.stdout) == len(templates)

    (tmp_path / "t.j2").write_text("{% if %}\n")
    (tmp_path / "_partials").mkdir()
    (tmp_path / "_partials" / "ok.j2").write_text("ok\n")
    preload_templates(tmp_path)
    with pytest.raises(ExportError):
        _render(tmp_path)
