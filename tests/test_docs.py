"""The docs site builds without a warning: a broken link, anchor or page fails.

``mkdocs build --strict`` (mkdocs.yml at the root, the pages in ``docs/``) into a temporary
folder; every page is in the site's navigation or named under ``not_in_nav``, and every page
of the navigation is linked from the README, which is where a reader starts.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]


def _config() -> dict[str, object]:
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))
    assert isinstance(config, dict)
    return config


def _nav_pages(nav: object) -> list[str]:
    """The page files of a mkdocs ``nav`` (nested sections flattened)."""
    if isinstance(nav, str):
        return [nav]
    if isinstance(nav, list):
        return [page for item in nav for page in _nav_pages(item)]
    if isinstance(nav, dict):
        return [page for item in nav.values() for page in _nav_pages(item)]
    return []


def test_the_site_builds_strictly(tmp_path: Path) -> None:
    """mkdocs --strict turns every warning (a link to a missing page or anchor) into a failure."""
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file",
         str(ROOT / "mkdocs.yml"), "--site-dir", str(tmp_path / "site")],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "WARNING" not in done.stderr, done.stderr
    for page in _nav_pages(_config()["nav"]):
        built = tmp_path / "site" / ("index.html" if page == "index.md" else page[:-3])
        html = built if built.suffix == ".html" else built / "index.html"
        assert html.is_file(), page
    assert (tmp_path / "site" / "images" / "viewer-office.png").is_file()


def test_a_broken_link_fails_the_build(tmp_path: Path) -> None:
    """The same build over a copy of the docs with one link to a missing anchor fails."""
    docs = tmp_path / "docs"
    docs.mkdir()
    for page in (ROOT / "docs").rglob("*"):
        if page.is_file():
            target = docs / page.relative_to(ROOT / "docs")
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(page.read_bytes())
    index = docs / "index.md"
    index.write_text(index.read_text(encoding="utf-8") + "\n[gone](service.md#no-such-section)\n")
    config = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    (tmp_path / "mkdocs.yml").write_text(config, encoding="utf-8")
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file",
         str(tmp_path / "mkdocs.yml"), "--site-dir", str(tmp_path / "site")],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert done.returncode != 0
    assert "no-such-section" in done.stderr


def test_every_page_is_in_the_navigation_and_the_readme() -> None:
    """A page of docs/ is in ``nav`` or ``not_in_nav``; the README links each page of ``nav``."""
    config = _config()
    nav = _nav_pages(config["nav"])
    waiting = str(config.get("not_in_nav", "")).split()
    pages = sorted(p.relative_to(ROOT / "docs").as_posix() for p in (ROOT / "docs").rglob("*.md"))
    assert [p for p in pages if p not in nav and f"/{p}" not in waiting] == []
    assert [p for p in nav if not (ROOT / "docs" / p).is_file()] == []
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    targets = re.findall(r"\]\(((?!https?:)[^)#]+)(?:#[^)]*)?\)", readme)
    assert [t for t in targets if not (ROOT / t).is_file()] == []  # no broken link either
    assert [p for p in nav if f"docs/{p}" not in targets] == []
