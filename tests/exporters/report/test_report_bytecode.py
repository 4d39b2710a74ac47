"""The report templates' compiled code is kept on disk, and a broken cache never fails a report."""

from __future__ import annotations

import tempfile
from pathlib import Path

import jinja2
import pytest

from exporters.report.bytecode import QuietBytecodeCache, bytecode_cache


def _environment(templates: Path, cache: jinja2.BytecodeCache | None) -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(templates), bytecode_cache=cache, autoescape=True
    )


def _compiles(env: jinja2.Environment, monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Record the templates ``env`` compiles from source."""
    compiled: list[str] = []
    compile_source = env.compile

    def recording(source: str, name: str | None = None, filename: str | None = None) -> object:
        compiled.append(name or "?")
        return compile_source(source, name, filename)

    monkeypatch.setattr(env, "compile", recording)
    return compiled


@pytest.fixture
def templates(tmp_path: Path) -> Path:
    folder = tmp_path / "templates"
    folder.mkdir()
    (folder / "page.j2").write_text("Hello {{ name }}!")
    return folder


def test_a_second_process_loads_the_compiled_template(
    tmp_path: Path, templates: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The first environment compiles and stores; a fresh one (a new process) only loads."""
    cache_dir = tmp_path / "cache"
    cache_dir.mkdir()
    first = _environment(templates, QuietBytecodeCache(str(cache_dir)))
    assert first.get_template("page.j2").render(name="site") == "Hello site!"
    assert len(list(cache_dir.iterdir())) == 1

    second = _environment(templates, QuietBytecodeCache(str(cache_dir)))
    compiled = _compiles(second, monkeypatch)
    assert second.get_template("page.j2").render(name="team") == "Hello team!"
    assert compiled == []


def test_an_edited_template_is_compiled_again(
    tmp_path: Path, templates: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The cache is checked against the template's source: an edit is never served stale."""
    cache_dir = tmp_path / "cache"
    cache_dir.mkdir()
    _environment(templates, QuietBytecodeCache(str(cache_dir))).get_template("page.j2")
    (templates / "page.j2").write_text("Goodbye {{ name }}.")

    fresh = _environment(templates, QuietBytecodeCache(str(cache_dir)))
    compiled = _compiles(fresh, monkeypatch)
    assert fresh.get_template("page.j2").render(name="site") == "Goodbye site."
    assert compiled == ["page.j2"]


def test_a_damaged_entry_is_compiled_from_source(tmp_path: Path, templates: Path) -> None:
    """An entry cut short or overwritten with other bytes does not fail the render."""
    cache_dir = tmp_path / "cache"
    cache_dir.mkdir()
    _environment(templates, QuietBytecodeCache(str(cache_dir))).get_template("page.j2")
    (entry,) = cache_dir.iterdir()
    for damage in (entry.read_bytes()[:20], b"j2" + bytes(range(256)) * 4, b""):
        entry.write_bytes(damage)
        env = _environment(templates, QuietBytecodeCache(str(cache_dir)))
        assert env.get_template("page.j2").render(name="x") == "Hello x!"


def test_a_cache_that_cannot_be_written_is_left_alone(tmp_path: Path, templates: Path) -> None:
    """A cache folder that is a file (or a full disk) costs the cache, not the report."""
    blocked = tmp_path / "not-a-folder"
    blocked.write_text("")
    env = _environment(templates, QuietBytecodeCache(str(blocked)))
    assert env.get_template("page.j2").render(name="x") == "Hello x!"


def test_no_cache_when_its_folder_cannot_be_made(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Jinja2's per-user folder under a temporary 'folder' that is a file: no cache."""
    blocker = tmp_path / "tmp-is-a-file"
    blocker.write_text("")
    monkeypatch.setattr(tempfile, "tempdir", str(blocker))
    assert bytecode_cache() is None
    assert isinstance(bytecode_cache(str(tmp_path)), QuietBytecodeCache)
